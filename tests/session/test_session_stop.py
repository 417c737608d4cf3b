"""A guided session stopped by a signal ends as a typed outcome (``GuidedSession.stopped``, the
recording's ``Stopped`` event), never as an exception the session raises for its own control flow; the
decay under way is closed complete and logged, and a stop before the release logs nothing.

Real parts: the session leads the built-in simulated MTi-G on a pty; the signal is a real SIGINT sent to
this process as the recording says held or released (a listener of its typed events, steering nothing
by text); the file is read back with the official ``mcap`` reader.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from mcap.reader import make_reader

from support.guided_session import Enter, signal_when
from tankdaq.acquire.events import DeviceReady, Event, Held, Notice, Released, Settled, Stopped
from tankdaq.acquire.listeners import EventLog
from tankdaq.config.plans import load_campaign_plan
from tankdaq.records import DecayEnd
from tankdaq.session.journal import SessionLog
from tankdaq.session.runner import GuidedSession, SessionSettings

ONE_CONDITION_PLAN = """hulls = ["swath"]
axis = "roll"
drafts = ["T"]
angles_deg = [10.0]
"""


@pytest.mark.parametrize("stop_at", [Held, Released])
@pytest.mark.slow
def test_a_signal_stops_the_session_as_an_outcome_and_the_decay_under_way_is_kept(
    tmp_path: Path, stop_at: type[Event]
) -> None:
    settings, out = _one_condition(tmp_path)
    signalled: list[Event] = []

    def react(event: Event) -> None:  # on the feeding (main) thread, as the daemon's signal handler runs
        if isinstance(event, stop_at) and not signalled:
            signalled.append(event)
            os.kill(os.getpid(), signal.SIGINT)

    heard = EventLog(react)
    operator = Enter()
    session = GuidedSession(settings, operator, listeners=[heard])
    state = session.run()  # returns: the stop is not an exception
    assert signalled, "the recording never reached the moment of the stop"
    assert session.stopped is not None and session.stopped.by == "SIGINT"
    assert heard.of(Stopped)[-1] == session.stopped
    assert operator.asked == ["draft"]  # nothing asked after the stop
    records = SessionLog(out).read()
    runs = [r for r in records if r["type"] == "run"]
    files = sorted(out.glob("*.mcap"))
    if stop_at is Held:  # stopped before a release: nothing recorded, nothing logged
        assert runs == [] and files == [] and not heard.of(Settled)
        assert state.decays == 0
        return
    (settled,) = heard.of(Settled)
    assert settled.outcome.ended is DecayEnd.STOPPED and settled.outcome.path in files
    (run,) = runs
    assert run["file"] == settled.outcome.path.name
    assert records[-1]["type"] == "verdict" and records[-1]["action"] == "stopped"
    with settled.outcome.path.open("rb") as f:  # complete: the official reader needs its summary
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None and summary.statistics.message_count > 0


@pytest.mark.slow
def test_session_stopped_mid_decay_exits_130_with_the_resume_advice(tmp_path: Path) -> None:
    """The command: SIGINT while a decay is being written (its file has data and is not yet in the log)."""
    import subprocess
    import sys

    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(ONE_CONDITION_PLAN)
    out = tmp_path / "out"
    exe = str(Path(sys.executable).with_name("tankdaq"))
    args = [exe, "session", str(plan_file), "--port", "sim", "--hull", "swath", "--out", str(out), "--yes"]
    args += ["--viewer", "none", "--sim-speed", "8", "--sim-faults", ""]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    writing = lambda: any(p.stat().st_size > 0 for p in out.glob("*.mcap"))  # noqa: E731
    err = signal_when(proc, writing, signal.SIGINT, "no decay under way")
    assert proc.returncode == 130, err
    assert "Traceback" not in err and f"continue with --resume --out {out}" in err
    records = SessionLog(out).read()
    assert records[-1]["type"] == "verdict" and records[-1]["action"] == "stopped"


def test_a_signal_while_the_device_opens_stops_the_session_before_any_question(
    tmp_path: Path, private_tempdir: Path
) -> None:
    """The session opens its device as it starts, before its first question: a Ctrl-C meanwhile (as the
    simulated sensor is started) ends ``run`` with ``stopped`` set, nothing asked, nothing left running."""
    settings, out = _one_condition(tmp_path)
    signalled: list[Event] = []

    def react(event: Event) -> None:
        if isinstance(event, Notice) and event.source == "device" and not signalled:
            signalled.append(event)
            os.kill(os.getpid(), signal.SIGINT)

    heard = EventLog(react)
    operator = Enter()
    session = GuidedSession(settings, operator, listeners=[heard])
    state = session.run()
    assert signalled and session.stopped == Stopped("SIGINT", 0) and heard.of(Stopped) == [session.stopped]
    assert operator.asked == [] and state.decays == 0 and not list(out.glob("*.mcap"))
    assert not heard.of(DeviceReady)  # stopped before the device was ready
    assert list(private_tempdir.iterdir()) == []  # the simulator it started is stopped, its pty gone


def _one_condition(tmp_path: Path) -> tuple[SessionSettings, Path]:
    """A session of the one-condition plan on the simulated sensor at 8x, and its folder."""
    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(ONE_CONDITION_PLAN)
    out = tmp_path / "out"
    record = {"port": "sim", "out_dir": out, "viewer": "none", "sim_speed": 8.0, "sim_seed": 3}
    return SessionSettings(load_campaign_plan(str(plan_file)), "swath", record, sim_faults={}), out
