"""A guided session holds one device for the whole session (issue 22): eight decays over two drafts, one
handshake. The simulated MTi-G's message log counts what the host sent it; each decay's file carries its
own condition, set on the stream between decays; the session moved on the recorder's typed events.

Real parts: the session leads the built-in simulated MTi-G on a pty (it plays each decay when the session
asks for it), the files are read back with the official ``mcap`` reader."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from support.guided_session import TWO_DRAFT_PLAN
from tankdaq.acquire.events import DeviceReady, ModelMoved, Released, Settled
from tankdaq.acquire.listeners import EventLog
from tankdaq.config.plans import load_campaign_plan
from tankdaq.session.journal import SessionLog
from tankdaq.session.runner import GuidedSession, SessionSettings
from tankdaq.store.reader import read_recording
from tankdaq.xsens.constants import MID


class Accepting:
    """An operator who says the draft is ready and keeps every decay (a flagged one too: the checks are
    another test's; this one counts decays on one device)."""

    def __init__(self) -> None:
        self.asked: list[str] = []

    def ask(self, question: Any) -> str:
        self.asked.append(question.kind)
        assert len(self.asked) < 40, "the session should have ended"
        return "a" if question.kind == "verdict" else ""


@pytest.mark.slow
def test_a_session_of_eight_decays_opens_the_device_once(tmp_path: Path) -> None:
    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(TWO_DRAFT_PLAN)
    out = tmp_path / "out"
    record = {
        "port": "sim",
        "out_dir": out,
        "viewer": "none",
        "sim_speed": 20.0,
        "sim_seed": 1,
        "model": "auto",
    }
    settings = SessionSettings(load_campaign_plan(str(plan_file)), "swath", record, sim_faults={})
    heard = EventLog()
    session = GuidedSession(settings, Accepting(), listeners=[heard])
    state = session.run()
    assert session.stopped is None
    accepted = [r for r in state.runs if r.verdict == "accepted"]
    assert len(accepted) == state.decays == 8
    assert session.stream is not None and session.stream.recorder.simulator is not None
    sent = [message.mid for message in session.stream.recorder.simulator.received]
    assert sent.count(MID.GOTO_CONFIG) == 1 and sent.count(MID.REQ_DID) == 1, sent  # one handshake
    assert len(heard.of(DeviceReady)) == 1
    assert heard.of(ModelMoved) == []  # watched between the eight decays: no drift, bump or level said
    # the decays the session asked for, on the one stream, each named by the session's decay number
    assert [e.run for e in heard.of(Released)] == [r.decay for r in state.runs]
    runs = [r for r in SessionLog(out).read() if r["type"] == "run"]
    settled = {e.outcome.path.name: e.outcome for e in heard.of(Settled) if e.outcome.path is not None}
    assert sorted(settled) == sorted(r["file"] for r in runs)
    for run in runs:  # each file carries its own condition, set on the stream between decays
        path = out / run["file"]
        with path.open("rb") as f:
            assert make_reader(f).get_summary() is not None, path
        metadata = read_recording(path).metadata
        assert float(metadata["angle_nominal_deg"]) == run["angle_deg"], metadata
        assert metadata["draft"] == run["draft"] and int(metadata["run"]) == run["decay"], metadata
