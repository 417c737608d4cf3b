"""While the operator is asked a question the guided session keeps feeding its one stream (issue 22): the
reader's queue does not pile up over a long pause, a decay released meanwhile is recorded and kept (logged
rejected, as a recording the log never heard of), and a SIGTERM at the question stops the session the
typed way: every file closed, the session resumable, the unanswered verdict asked again.

Real parts: the built-in simulated MTi-G on a pty (played a decay while the question is open), a real
``tankdaq session`` process with a terminal (a pty) waiting at its verdict question, the files read
back with the official ``mcap`` reader. What the tests wait for are typed events, the blocks fed and the
session file, each with a bound.
"""

from __future__ import annotations

import dataclasses
import os
import pty
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from support.guided_session import signal_when
from tankdaq.acquire.decay import LiveDecay
from tankdaq.acquire.events import Released, Settled
from tankdaq.acquire.listeners import EventLog
from tankdaq.acquire.sinks import Sink
from tankdaq.config.plans import load_campaign_plan
from tankdaq.device.driver import StreamBlock
from tankdaq.records import DecayEnd
from tankdaq.session.journal import SessionLog
from tankdaq.session.runner import GuidedSession, SessionSettings

ONE_CONDITION_PLAN = """hulls = ["swath"]
axis = "roll"
drafts = ["T"]
angles_deg = [10.0]
[acceptance]
angle_tolerance_deg = 1.5
"""
#: Blocks (20 ms reads) the stream must feed while the question is open: a second of a pause at least.
FED_AT_THE_QUESTION = 50
#: The most blocks the reader may hold at any check meanwhile (2 s of reads; without feeding it grows
#: by 50 a second, up to its 3000).
QUEUE_BOUND = 100
WAIT_S = 120.0


class Fed(Sink):
    """Counts the blocks the pipeline was fed; ``wait_until`` a condition, checked as each block comes."""

    def __init__(self) -> None:
        self.blocks = 0
        self._fed = threading.Condition()

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> None:
        with self._fed:
            self.blocks += 1
            self._fed.notify_all()

    def wait_until(self, condition: Callable[[], bool], timeout_s: float) -> bool:
        with self._fed:
            return self._fed.wait_for(condition, timeout_s)


class Pausing:
    """Says the draft is ready; at the verdict it pauses: the simulated sensor plays another decay (the
    operator tilted and let go while the question was open), and the answer comes only once that decay
    settled and the stream fed a second's blocks at least. The reader's queue is read at each block."""

    def __init__(self, fed: Fed, heard: EventLog) -> None:
        self.fed, self.heard = fed, heard
        self.session: GuidedSession | None = None
        self.asked: list[str] = []
        self.fed_at_question = -1
        self.queued: list[int] = []

    def ask(self, question: Any) -> str:
        self.asked.append(question.kind)
        if question.kind == "draft" or len(self.asked) > 2:
            return "" if question.kind == "draft" else "s"
        assert self.session is not None and self.session.stream is not None
        daemon = self.session.stream.recorder
        assert daemon.simulator is not None
        daemon.simulator.play(dataclasses.replace(daemon.simulation_scenario(), seed=77))
        start = self.fed.blocks

        def settled_meanwhile() -> bool:
            self.queued.append(daemon.queued_blocks)
            done = [e for e in self.heard.of(Settled) if e.outcome.run == 2]
            return bool(done) and self.fed.blocks - start >= FED_AT_THE_QUESTION

        self.fed.wait_until(settled_meanwhile, WAIT_S)
        self.fed_at_question = self.fed.blocks - start
        return "s"  # reject and skip the condition: the session ends (no report to fit)


@pytest.mark.slow
def test_a_question_keeps_the_stream_fed_and_a_release_meanwhile_is_kept(tmp_path: Path) -> None:
    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(ONE_CONDITION_PLAN)
    out = tmp_path / "out"
    record = {"port": "sim", "out_dir": out, "viewer": "none", "sim_speed": 20.0, "sim_seed": 2}
    settings = SessionSettings(load_campaign_plan(str(plan_file)), "swath", record, sim_faults={})
    fed, heard = Fed(), EventLog()
    operator = Pausing(fed, heard)
    session = GuidedSession(settings, operator, listeners=[fed, heard])
    operator.session = session
    state = session.run()
    assert operator.asked == ["draft", "verdict"] and session.stopped is None
    assert operator.fed_at_question >= FED_AT_THE_QUESTION  # the stream was fed while the question waited
    assert operator.queued and max(operator.queued) <= QUEUE_BOUND, operator.queued
    # the decay released while the question was open: recorded whole, kept, logged rejected
    assert [e.run for e in heard.of(Released)] == [1, 2]
    (between,) = [e.outcome for e in heard.of(Settled) if e.outcome.run == 2]
    assert between.ended is DecayEnd.SETTLED and between.path is not None and between.path.is_file()
    runs = {r.decay: r for r in state.runs}
    assert runs[1].verdict == runs[2].verdict == "rejected"
    assert runs[2].file == between.path.name
    records = SessionLog(out).read()
    (verdict,) = [r for r in records if r["type"] == "verdict" and r["decay"] == 2]
    assert verdict["action"] == "between decays"


def _session_args(plan: Path, out: Path, *extra: str) -> list[str]:
    exe = str(Path(sys.executable).with_name("tankdaq"))
    return [exe, "session", str(plan), "--port", "sim", "--hull", "swath", "--out", str(out),
            "--viewer", "none", "--sim-speed", "20", "--sim-faults", "", *extra]  # fmt: skip


def _verdict_open(out: Path) -> bool:
    """The session file holds a decay and no verdict on it: the verdict question is being asked."""
    records = SessionLog(out).read()
    return any(r["type"] == "run" for r in records) and not any(r["type"] == "verdict" for r in records)


@pytest.mark.slow
def test_sigterm_at_the_verdict_question_stops_the_session_and_resume_asks_it_again(tmp_path: Path) -> None:
    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(ONE_CONDITION_PLAN)
    out = tmp_path / "out"
    answers = tmp_path / "answers.txt"
    answers.write_text("\n")  # Enter at the draft question; the verdict waits at the terminal
    terminal, operator_side = pty.openpty()
    proc = subprocess.Popen(
        _session_args(plan_file, out, "--responses", str(answers)),
        stdin=operator_side,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    os.close(operator_side)
    try:
        ready = lambda: out.is_dir() and _verdict_open(out)  # noqa: E731
        err = signal_when(proc, ready, signal.SIGTERM, "no verdict question", WAIT_S)
    finally:
        os.close(terminal)
    assert proc.returncode == 130, err  # stopped the typed way (SIGTERM's default would be -15)
    assert "Traceback" not in err and f"continue with --resume --out {out}" in err
    records = SessionLog(out).read()
    (run,) = [r for r in records if r["type"] == "run"]
    assert not [r for r in records if r["type"] == "verdict"]  # unanswered, not judged for the operator
    with (out / run["file"]).open("rb") as f:  # the decay's file complete: the reader needs its summary
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None and summary.statistics.message_count > 0

    answers.write_text("s\n")  # on resume: the verdict first, answered "skip the condition"
    resumed = subprocess.run(
        _session_args(plan_file, out, "--resume", "--responses", str(answers)),
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=WAIT_S,
    )
    assert resumed.returncode == 0, resumed.stderr
    records = SessionLog(out).read()
    starts = [i for i, r in enumerate(records) if r["type"] == "start"]
    after = records[starts[-1] :]
    (verdict,) = [r for r in after if r["type"] == "verdict"]
    assert verdict["decay"] == run["decay"] and verdict["action"] == "reject and skip the condition"
    assert not [r for r in after if r["type"] == "run"]  # the verdict was asked first: nothing recorded
