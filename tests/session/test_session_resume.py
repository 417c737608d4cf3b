"""A session resumes whatever its log and folder hold: every unusable line of session.jsonl is listed and
skipped, and a decay whose recording was deleted since is marked rejected, recorded again on the
simulated MTi-G, and the report written over the decays that exist (issue 19)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from support.guided_session import Enter
from tankdaq.config.plans import load_campaign_plan
from tankdaq.records import DecayEnd
from tankdaq.session.checks import Measured
from tankdaq.session.journal import SessionLog
from tankdaq.session.runner import GuidedSession, SessionSettings
from tankdaq.session.state import SessionState

PLAN = """description = "one condition, one repeat"
hulls = ["swath"]
axis = "roll"
drafts = ["T"]
angles_deg = [10.0]
[acceptance]
angle_tolerance_deg = 1.5
"""

MEASURED = dataclasses.asdict(
    Measured(
        10.1,
        0.02,
        DecayEnd.SETTLED,
        16,
        0.997,
        {"b1": 0.03, "b2": 4.6, "c1": 14.3},
        1.66,
        2.6,
        40.0,
        "record",
    )
)


def test_unusable_lines_are_listed_and_skipped(tmp_path: Path) -> None:
    log = SessionLog(tmp_path)
    log.append("plan", plan={"name": "x"})
    with log.path.open("ab") as fh:
        fh.write(b'{"type": "note", "text": "caf\xe9"}\n')  # Latin-1 from an editor
        fh.write(b'["a", "list"]\n')
        fh.write(b'{"type": "run", "decay": 2}\n')  # no file, no draft
        fh.write(b'{"type": "run", "decay": 3, "draft": "T", "angle_deg": 10, "file": "../../etc/x.mcap", '
                 b'"reasons": [], "measured": {}}\n')  # fmt: skip
        fh.write(b"[" * 100_000 + b"\n")
    log.append("note", text="after")
    records = log.read()
    assert [r["type"] for r in records] == ["plan", "note"] and log.lines == [1, 7]
    assert [line.split(" skipped: ")[1] for line in log.skipped] == [
        "not UTF-8 text",
        "a JSON list, not a record",
        "a run record without a draft (draft)",
        "a run record without a file name in the session folder (file)",
        "not a whole JSON line (cut by a crash, or edited)",
    ]
    assert all(
        line.startswith(f"session.jsonl line {n} ")
        for n, line in zip([2, 3, 4, 5, 6], log.skipped, strict=True)
    )


def test_records_that_contradict_the_log_are_left_out(tmp_path: Path) -> None:
    run = {
        "type": "run",
        "draft": "T",
        "angle_deg": 10.0,
        "file": "a.mcap",
        "reasons": [],
        "measured": MEASURED,
    }
    records = [
        {**run, "decay": 1},
        {**run, "decay": 1, "file": "b.mcap"},  # the same decay twice
        {"type": "verdict", "decay": 7, "verdict": "accepted"},  # no such decay
        {**run, "decay": 2, "measured": {"angle_deg": "ten"}},  # measured values unusable
        {"type": "verdict", "decay": 1, "verdict": "accepted"},
    ]
    state = SessionState.from_log(records, [], 1)
    assert [(r.decay, r.file, r.verdict) for r in state.runs] == [(1, "a.mcap", "accepted")]
    assert [p.split(" skipped: ")[1] for p in state.problems] == [
        "decay 1 was logged before",
        "no decay 7 was logged",
        "its measured values are incomplete",
    ]
    assert state.next_decay == 2


@pytest.mark.slow
def test_a_deleted_recording_is_redone_and_the_report_still_written(tmp_path: Path) -> None:
    """The log says decay 1 was accepted and the report written; its file was deleted since, and the
    log picked up garbage. The resume lists the garbage, marks decay 1 rejected, records decay 2 on the
    simulator, and writes the report over decay 2 (a file that exists)."""
    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(PLAN)
    plan = load_campaign_plan(str(plan_file))
    out = tmp_path / "out"
    out.mkdir()
    log = SessionLog(out)
    log.append("plan", plan=dataclasses.asdict(plan), hull="swath", conditions=[])
    log.append("start", resumed=False)
    log.append("draft", draft="T", action="ready")
    log.append("run", decay=1, draft="T", angle_deg=10.0, file="gone.mcap", reasons=[], measured=MEASURED)
    log.append("verdict", decay=1, verdict="accepted", action="accept")
    log.append("report", files=["report/campaign.csv"], decays=["gone.mcap"])
    with log.path.open("ab") as fh:
        fh.write(b"\xff\xfe not text\n[1, 2]\n")
    lines: list[str] = []
    settings = SessionSettings(
        plan, "swath", {"port": "sim", "out_dir": out, "viewer": "none", "sim_speed": 20.0, "sim_seed": 3}
    )
    operator = Enter(limit=6)
    state = GuidedSession(settings, operator, on_line=lines.append, resume=True).run()

    assert lines[:2] == [
        "session.jsonl line 7 skipped: not UTF-8 text",
        "session.jsonl line 8 skipped: a JSON list, not a record",
    ]
    assert f"decay 1: gone.mcap is gone from {out}; marked rejected, T 10 deg is recorded again" in lines
    runs = {r.decay: r for r in state.runs}
    assert runs[1].verdict == "rejected" and runs[2].verdict == "accepted"
    assert (out / runs[2].file).is_file() and operator.asked == ["draft", "verdict"]
    records = [json.loads(line) for line in log.path.read_bytes().splitlines()[8:]]
    report = [r for r in records if r["type"] == "report"]
    assert len(report) == 1 and report[0]["decays"] == [runs[2].file]
    assert (out / "report" / "campaign.csv").read_text().count("\n") == 2  # header and decay 2's condition
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "plan.toml"]  # nothing outside --out
