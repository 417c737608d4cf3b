"""The guided test session, end to end on the simulated MTi-G: a real subprocess, killed for real
(SIGKILL) mid-decay, then resumed; the session file, the recordings, the report and the campaign
panel (.rrd) read back."""

from __future__ import annotations

import csv
import dataclasses
import json
import signal
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import pytest
from rerun.chunk import RrdReader
from typer.testing import CliRunner

from support.guided_session import TWO_DRAFT_PLAN
from support.measured_decay import measured_decay
from tankdaq.cli import app
from tankdaq.session.journal import LOG_NAME, SessionLock, SessionLog

pytestmark = pytest.mark.filterwarnings("ignore:RRD file has no footer")

EXE = [str(Path(sys.executable).with_name("tankdaq"))]  # the installed command, as the operator runs it
DEADLINE_S = 240.0


def _session_args(plan: Path, out: Path, *extra: str) -> list[str]:
    return [
        *EXE,
        "session",
        str(plan),
        "--port",
        "sim",
        "--hull",
        "swath",
        "--out",
        str(out),
        "--viewer",
        "save",
        "--sim-speed",
        "20",
        "--sim-faults",
        "2:wrong-angle,6:double-push",
        "--seed",
        "0",
        "--catalogue",
        str(out.parent / "catalogue.sqlite"),
        *extra,
    ]


def _records(out: Path) -> list[dict[str, Any]]:
    return SessionLog(out).read()


def _decay_under_way(out: Path) -> bool:
    """After three decays, a recording with data on disk that the session file does not list yet: a
    decay is being recorded."""
    logged = {r["file"] for r in _records(out) if r["type"] == "run"}
    return len(logged) >= 3 and any(p.name not in logged and p.stat().st_size > 0 for p in out.glob("*.mcap"))


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Run the plan, SIGKILL the session mid-decay after the third decay, resume it to the end."""
    folder = tmp_path_factory.mktemp("session")
    plan = folder / "plan.toml"
    plan.write_text(TWO_DRAFT_PLAN)
    out = folder / "out"
    responses = folder / "answers.txt"
    responses.write_text("# the operator's first answers\nn water calm, model trimmed\n\n")
    proc = subprocess.Popen(
        _session_args(plan, out, "--responses", str(responses), "--yes"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        deadline = time.monotonic() + DEADLINE_S
        while not (out.is_dir() and _decay_under_way(out)):
            assert proc.poll() is None, f"the session ended before it was killed:\n{proc.stdout.read()}"
            assert time.monotonic() < deadline, "no decay under way after three"
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
    first_output = proc.stdout.read()
    proc.stdout.close()
    killed_lock_pid = int((out / "session.lock").read_text().split()[0])
    files_at_kill = sorted(p.name for p in out.glob("*.mcap"))
    resumed = subprocess.run(
        _session_args(plan, out, "--resume", "--yes"), capture_output=True, text=True, timeout=DEADLINE_S
    )
    return {
        "out": out,
        "plan": plan,
        "killed_returncode": proc.returncode,
        "killed_pid": proc.pid,
        "killed_lock_pid": killed_lock_pid,
        "files_at_kill": files_at_kill,
        "first_output": first_output,
        "resumed": resumed,
    }


@pytest.mark.slow
def test_the_kill_is_real_and_the_resume_finishes(session: dict[str, Any]) -> None:
    assert session["killed_returncode"] == -signal.SIGKILL
    assert session["killed_lock_pid"] == session["killed_pid"]  # its lock was left behind, and did not block
    resumed = session["resumed"]
    assert resumed.returncode == 0, resumed.stderr
    assert "session done: 8 decays accepted" in resumed.stderr


@pytest.mark.slow
def test_every_recording_is_in_the_session_file_with_its_verdict(session: dict[str, Any]) -> None:
    out = session["out"]
    records = _records(out)
    runs = [r for r in records if r["type"] == "run"]
    verdicts = {r["decay"]: r["verdict"] for r in records if r["type"] == "verdict"}
    files = sorted(p.name for p in out.glob("*.mcap"))
    assert sorted(r["file"] for r in runs) == files  # every file listed once, none missing
    assert set(session["files_at_kill"]) <= set(files)  # nothing recorded before the kill is gone
    assert [r["decay"] for r in runs] == list(range(1, len(runs) + 1))
    assert set(verdicts) == {r["decay"] for r in runs}  # every decay judged
    assert sum(v == "accepted" for v in verdicts.values()) == 8
    per_condition = defaultdict(int)
    for r in runs:
        if verdicts[r["decay"]] == "accepted":
            per_condition[(r["draft"], r["angle_deg"])] += 1
    assert per_condition == {("T", 10.0): 2, ("T", 15.0): 2, ("1.1T", 10.0): 2, ("1.1T", 15.0): 2}
    starts = [r for r in records if r["type"] == "start"]
    assert [s["resumed"] for s in starts] == [False, True]
    levels = [r for r in records if r["type"] == "level"]  # measured before each draft's first decay
    assert {r["draft"] for r in levels} == {"T", "1.1T"} and all(r["ok"] for r in levels)
    assert all(abs(r["angle_deg"]) < 0.5 and r["sd_deg"] < 0.3 for r in levels)
    notes = [r for r in records if r["type"] == "note"]
    assert [n["text"] for n in notes] == ["water calm, model trimmed"]


@pytest.mark.slow
def test_the_catalogue_lists_exactly_the_accepted_decays_of_a_draft(session: dict[str, Any]) -> None:
    """``tankdaq runs --hull swath --draft T --json``: the session's accepted decays at T, no other (the
    session killed mid-decay and resumed wrote its catalogue as it went)."""
    out = session["out"]
    records = _records(out)
    verdicts = {r["decay"]: r["verdict"] for r in records if r["type"] == "verdict"}
    runs = [r for r in records if r["type"] == "run"]
    accepted = {
        str((out / r["file"]).resolve())
        for r in runs
        if verdicts[r["decay"]] == "accepted" and r["draft"] == "T"
    }
    catalogue = str(out.parent / "catalogue.sqlite")
    result = CliRunner().invoke(
        app, ["runs", "--hull", "swath", "--draft", "T", "--json", "--catalogue", catalogue]
    )
    assert result.exit_code == 0, result.output
    listed = json.loads(result.stdout)
    assert len(listed) == len(accepted) == 4 and {row["path"] for row in listed} == accepted
    assert all(row["verdict"] == "accepted" and row["complete"] and row["r2_angle"] > 0.9 for row in listed)
    assert len({row["session_id"] for row in listed}) == 1
    rejected = CliRunner().invoke(app, ["runs", "--verdict", "rejected", "--json", "--catalogue", catalogue])
    assert {Path(row["path"]).name for row in json.loads(rejected.stdout)} == {
        r["file"] for r in runs if verdicts[r["decay"]] == "rejected"
    }


@pytest.mark.slow
def test_the_wrong_angle_is_flagged_and_repeated(session: dict[str, Any]) -> None:
    records = _records(session["out"])
    runs = {r["decay"]: r for r in records if r["type"] == "run"}
    verdicts = {r["decay"]: r for r in records if r["type"] == "verdict"}
    wrong = runs[2]
    assert wrong["measured"]["angle_deg"] > 13.0  # the simulator tilted 1.5 x 10 deg
    assert any("from the nominal 10" in reason for reason in wrong["reasons"])
    assert verdicts[2]["verdict"] == "rejected" and verdicts[2]["action"] == "reject and repeat"
    assert (runs[3]["draft"], runs[3]["angle_deg"]) == (wrong["draft"], wrong["angle_deg"])
    assert runs[3]["reasons"] == [] and verdicts[3]["verdict"] == "accepted"


@pytest.mark.slow
def test_the_decay_cut_by_the_kill_is_kept_and_rejected(session: dict[str, Any]) -> None:
    records = _records(session["out"])
    recovered = [r for r in records if r["type"] == "verdict" and r["action"] == "recovered"]
    assert len(recovered) == 1
    (run,) = [r for r in records if r["type"] == "run" and r["decay"] == recovered[0]["decay"]]
    assert run["file"] in session["files_at_kill"]
    assert (session["out"] / run["file"]).stat().st_size > 0


@pytest.mark.slow
def test_the_double_push_is_flagged(session: dict[str, Any]) -> None:
    records = _records(session["out"])
    (pushed,) = [r for r in records if r["type"] == "run" and r["decay"] == 6]
    assert any(reason.startswith("release not clean") for reason in pushed["reasons"])


@pytest.mark.slow
def test_the_report_covers_only_the_accepted_decays(session: dict[str, Any]) -> None:
    out = session["out"]
    records = _records(out)
    verdicts = {r["decay"]: r["verdict"] for r in records if r["type"] == "verdict"}
    accepted = {r["file"] for r in records if r["type"] == "run" and verdicts[r["decay"]] == "accepted"}
    with (out / "report" / "campaign.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 and all(row["runs"] == "2" and row["error"] == "" for row in rows)
    reported = {Path(name).name for row in rows for name in row["files"].split()}
    assert reported == accepted
    with (out / "report" / "repeat_spread.csv").open() as fh:
        spread = list(csv.DictReader(fh))
    assert len(spread) == 4 and all(float(row["c1_repeat_sd"]) > 0 for row in spread)
    (report,) = [r for r in records if r["type"] == "report"]
    assert sorted(report["decays"]) == sorted(accepted)
    text = (out / "report" / "campaign.md").read_text()
    assert "## Repeat-to-repeat spread" in text and "(1σ, scatter of repeats)" in text
    assert "## IMO table" in text and "Bertin's N" in text  # the session's decays give its IMO table


def _rrd_rows(path: Path) -> tuple[dict[str, int], dict[str, dict[str, Any]]]:
    """Temporal rows per entity and the latest static components per entity of a .rrd."""
    reader = RrdReader(path)
    (recording,) = reader.recordings()
    counts: dict[str, int] = defaultdict(int)
    static: dict[str, dict[str, Any]] = defaultdict(dict)
    for chunk in reader.stream(store=recording).to_chunks():
        batch = chunk.to_record_batch()
        if chunk.is_static:
            for name in batch.schema.names:
                if ":" in name:
                    static[chunk.entity_path][name] = batch.column(name).to_pylist()[-1]
        elif any(name.startswith("Scalars:") for name in batch.schema.names):
            counts[chunk.entity_path] += batch.num_rows
    return counts, static


@pytest.mark.slow
def test_the_campaign_panel_has_one_point_per_accepted_condition(session: dict[str, Any]) -> None:
    counts, static = _rrd_rows(session["out"] / "campaign.rrd")
    records = _records(session["out"])
    accepted = {r["decay"] for r in records if r["type"] == "verdict" and r["verdict"] == "accepted"}
    for draft in ("T", "1.1T"):
        assert counts[f"/campaign/b_eq/{draft}"] == 2
        terms = Counter(  # per term, the conditions whose accepted repeats' chosen models hold it
            term
            for angle in (10.0, 15.0)
            for term in {
                term
                for r in records
                if r["type"] == "run"
                and r["decay"] in accepted
                and (r["draft"], r["angle_deg"]) == (draft, angle)
                for term in r["measured"]["coefficients"]
            }
        )
        assert terms["b1"] == terms["c1"] == 2
        for term, count in terms.items():
            assert counts[f"/campaign/coefficients/{term}/{draft}"] == count
    labels = static["/campaign/matrix"]["Points2D:labels"]
    assert len(labels) == 4 and all(": accepted 2/2" in label for label in labels)


# ---- the parts on their own ---------------------------------------------------------------------------


def test_a_second_session_cannot_write_the_same_folder(tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text(TWO_DRAFT_PLAN)
    with SessionLock(tmp_path):
        result = CliRunner().invoke(
            app, ["session", str(plan), "--port", "sim", "--hull", "swath", "--out", str(tmp_path), "--yes"]
        )
    assert result.exit_code == 2
    assert "another session (pid" in result.output


def test_a_folder_with_a_session_needs_resume_and_the_same_plan(tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text(TWO_DRAFT_PLAN)
    base = ["session", str(plan), "--port", "sim", "--hull", "swath", "--out", str(tmp_path / "out"), "--yes"]
    result = CliRunner().invoke(app, [*base, "--resume"])
    assert result.exit_code == 2 and "no session to resume" in result.output
    (tmp_path / "out").mkdir(exist_ok=True)
    SessionLog(tmp_path / "out").append("plan", plan={}, hull="swath")
    result = CliRunner().invoke(app, base)
    assert result.exit_code == 2 and "give --resume" in result.output
    result = CliRunner().invoke(app, [*base, "--resume"])
    assert result.exit_code == 2 and "another plan or hull" in result.output


def test_a_hull_outside_the_plan_is_refused_before_anything_opens(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app,
        [
            "session",
            "seed000-trimaran-catamaran-pitch",
            "--port",
            "sim",
            "--hull",
            "swath",
            "--out",
            str(tmp_path),
            "--yes",
        ],
    )
    assert result.exit_code == 2
    assert "covers trimaran, catamaran, not swath" in result.output
    assert not (tmp_path / LOG_NAME).exists()


def test_help_explains_the_plan_format() -> None:
    result = CliRunner().invoke(app, ["session", "--help"], terminal_width=120)
    assert result.exit_code == 0
    for word in ("repeats", "[acceptance]", "angle_tolerance_deg", "--resume", "session.jsonl"):
        assert word in result.output


def test_a_line_cut_by_a_crash_is_skipped_and_the_next_starts_fresh(tmp_path: Path) -> None:
    log = SessionLog(tmp_path)
    log.append("plan", plan={"name": "x"})
    with log.path.open("a") as fh:
        fh.write('{"type": "run", "decay": 1, "fi')  # the power went here
    log.append("note", text="after the crash")
    assert [r["type"] for r in log.read()] == ["plan", "note"]


class _Answers:
    """An operator with scripted answers who walks away (Ctrl-C) when they run out."""

    def __init__(self, *answers: str) -> None:
        self.answers = list(answers)
        self.asked: list[str] = []

    def ask(self, question: Any) -> str:
        self.asked.append(question.kind)
        if not self.answers:
            raise KeyboardInterrupt
        return self.answers.pop(0)


def test_a_decay_recorded_but_not_judged_is_judged_first_on_resume(tmp_path: Path) -> None:

    from tankdaq.config.plans import load_campaign_plan
    from tankdaq.session.runner import GuidedSession, SessionSettings

    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(TWO_DRAFT_PLAN)
    plan = load_campaign_plan(str(plan_file))
    out = tmp_path / "out"
    out.mkdir()
    log = SessionLog(out)
    log.append("plan", plan=dataclasses.asdict(plan), hull="swath", conditions=[])
    log.append("start", resumed=False)
    log.append("draft", draft="T", action="ready")
    measured = dataclasses.asdict(measured_decay())
    log.append("run", decay=1, draft="T", angle_deg=10.0, file="a.mcap", reasons=[], measured=measured)
    (out / "a.mcap").write_bytes(b"")  # its file is in the folder (a decay whose file is gone is re-done)
    # the power went before the operator answered
    settings = SessionSettings(plan, "swath", {"port": "sim", "out_dir": out, "viewer": "none"})
    operator = _Answers("n judged after the restart", "a")
    with pytest.raises(KeyboardInterrupt):
        GuidedSession(settings, operator, resume=True).run()
    assert operator.asked == ["verdict", "verdict", "draft"]  # the verdict first, then the draft again
    records = log.read()
    kinds = [r["type"] for r in records]
    assert kinds[-3:] == ["start", "note", "verdict"]
    assert records[-1]["decay"] == 1 and records[-1]["verdict"] == "accepted"
    assert records[-2]["text"] == "judged after the restart"


# ---- physics: an implausible fit is never accepted silently ------------------------------------------

PLAN_15 = """hulls = ["swath"]
axis = "roll"
drafts = ["T"]
angles_deg = [15.0]
"""


def _run_session(tmp_path: Path, *extra: str) -> tuple[Path, list[dict[str, Any]]]:
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN_15)
    out = tmp_path / "out"
    args = ["session", str(plan), "--port", "sim", "--hull", "swath", "--out", str(out), "--viewer", "save"]
    result = CliRunner().invoke(app, [*args, "--sim-speed", "20", "--sim-faults", "", "--yes", *extra])
    assert result.exit_code == 0, result.output
    return out, _records(out)


@pytest.mark.slow
def test_a_swath_session_with_the_default_model_accepts_positive_damping(tmp_path: Path) -> None:
    _, records = _run_session(tmp_path)
    (run,) = [r for r in records if r["type"] == "run"]
    (verdict,) = [r for r in records if r["type"] == "verdict"]
    assert verdict["verdict"] == "accepted" and run["reasons"] == []
    measured = run["measured"]
    assert measured["fit_warnings"] == [] and measured["coefficients"]["b1"] > 0
    assert measured["b_eq_per_s"] > 0


@pytest.mark.slow
def test_an_implausible_fit_asks_and_yes_gives_up_after_the_cap(tmp_path: Path) -> None:
    from tankdaq.session.operator import MAX_REJECTED

    out, records = _run_session(tmp_path, "--model", "b1,b2,c1,c3")  # b1 < 0 on SWATH decays from 15 deg
    verdicts = [r for r in records if r["type"] == "verdict"]
    assert [v["action"] for v in verdicts] == ["reject and repeat"] * (MAX_REJECTED - 1) + [
        "reject and skip the condition"
    ]
    for verdict in verdicts:
        assert verdict["verdict"] == "rejected"
        assert any(reason.startswith("fit: implausible damping: B_eq -") for reason in verdict["reasons"])
    assert [r["type"] for r in records].count("skip") == 1
    rrd = sorted(out.glob("*_run01.rrd"))[0]  # the live view says it too, in its event log
    reader = RrdReader(rrd)
    (recording,) = reader.recordings()
    texts = []
    for chunk in reader.stream(store=recording).to_chunks():
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/events" and "TextLog:text" in batch.schema.names:
            levels = batch.column("TextLog:level").to_pylist()
            texts += [
                (t[0], lv[0]) for t, lv in zip(batch.column("TextLog:text").to_pylist(), levels, strict=True)
            ]
    implausible = [(text, level) for text, level in texts if "implausible damping" in text]
    assert implausible and all(level == "WARN" for _, level in implausible)
