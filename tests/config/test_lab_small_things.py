"""The small things a lab hits (issue 42, item 6): a hull or plan saved with a byte-order mark by Windows
Notepad is read; ``session --resume`` on an empty or damaged log says what is wrong with it; long work
says where it is when stderr is a pipe; ``runs --verdict rejected`` shows why each run was rejected."""

from __future__ import annotations

import codecs
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.config.hulls import load_hull
from tankdaq.config.plans import load_campaign_plan
from tankdaq.session.journal import SessionLog

runner = CliRunner()

HULL = """name = "bom"
description = "a hull saved by Notepad"
[dimensions]
displacement_kg = 20.0
[axes.roll]
gm_m = 0.05
radius_of_gyration_m = 0.12
"""

PLAN = """hulls = ["swath"]
axis = "roll"
drafts = ["T"]
angles_deg = [10.0]
"""


def one_line(args: list[str], code: int) -> str:
    """``tankdaq ARGS`` exits ``code`` with one line, no traceback; the line."""
    result = runner.invoke(app, args)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == code, result.output
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    return lines[0]


# ---- a byte-order mark ----------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_hull_and_a_plan_saved_with_a_bom_are_read(tmp_path: Path) -> None:
    hull, plan = tmp_path / "bom.toml", tmp_path / "plan.toml"
    hull.write_bytes(codecs.BOM_UTF8 + HULL.encode())
    plan.write_bytes(codecs.BOM_UTF8 + PLAN.encode())
    assert load_hull(str(hull)).name == "bom"
    assert load_campaign_plan(str(plan)).angles_deg == [10.0]
    result = runner.invoke(app, ["hulls", "show", str(hull)])
    assert result.exit_code == 0 and "a hull saved by Notepad" in result.output, result.output


@pytest.mark.slow
def test_a_utf16_file_is_named_and_a_bad_one_still_says_where(tmp_path: Path) -> None:
    utf16 = tmp_path / "utf16.toml"
    utf16.write_bytes(HULL.encode("utf-16"))  # Notepad's "Unicode": a BOM, then two bytes a character
    assert "saved as UTF-16 (Unicode); save it as UTF-8" in one_line(["hulls", "show", str(utf16)], 2)
    broken = tmp_path / "broken.toml"
    broken.write_bytes(codecs.BOM_UTF8 + b'name = "x"\n\ngm_m = ]\n')
    line = one_line(["hulls", "show", str(broken)], 2)
    assert "not valid TOML" in line and "line 3" in line  # the line after the mark, as an editor counts


# ---- session --resume on a log it cannot resume ----------------------------------------------------------


@pytest.mark.parametrize(
    ("log", "code", "said"),
    [
        (b"", 2, "session.jsonl is empty"),
        (b"\n  \n", 2, "session.jsonl is empty"),
        (b'{"type": "plan", "plan": {"descr\n', 1, "session.jsonl line 1 skipped: not a whole JSON line"),
        (
            b'{"type": "pl\n{"type": "start", "resumed": false}\n',
            1,
            "session.jsonl line 1 skipped: not a whole JSON line",
        ),
        (b'{"type": "start", "resumed": false}\n', 1, "session.jsonl line 1 is not the session's plan"),
    ],
    ids=["empty", "blank lines", "line 1 cut", "line 1 cut, more after", "no plan"],
)
@pytest.mark.slow
def test_resume_names_what_is_wrong_with_the_log(log: bytes, code: int, said: str, tmp_path: Path) -> None:
    plan, out = tmp_path / "plan.toml", tmp_path / "out"
    plan.write_text(PLAN)
    out.mkdir()
    (out / "session.jsonl").write_bytes(log)
    args = ["session", str(plan), "--port", "sim", "--hull", "swath", "--out", str(out), "--yes", "--resume"]
    line = one_line(args, code)
    assert said in line and "missing" not in line, line
    assert ("without --resume" if code == 2 else "another --out") in line, line
    assert (out / "session.jsonl").read_bytes() == log  # the log is left as it was


# ---- progress in a pipe ----------------------------------------------------------------------------------

#: A task of 40 steps, 3 s apart on an injected clock, through the command line's progress with stderr
#: a pipe: 120 s of "work" that takes no time.
PIPED = textwrap.dedent(
    """
    import itertools
    from tankdaq.cli.app import TerminalProgress

    ticks = itertools.count(0.0, 3.0)
    progress = TerminalProgress(clock=lambda: next(ticks))
    with progress.task("bootstrap", total=40) as update:
        for done in range(1, 41):
            update(done)
    """
)


@pytest.mark.slow
def test_long_work_says_where_it_is_when_stderr_is_a_pipe() -> None:
    done = subprocess.run(
        [sys.executable, "-c", PIPED], stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) >= 2 and lines[-1].endswith(", done"), done.stderr
    assert all(line.startswith("bootstrap: ") and "/40 after " in line for line in lines), done.stderr
    said = [float(line.split(" after ")[1].split(" s")[0]) for line in lines]
    assert all(later - earlier <= 12.0 for earlier, later in zip([0.0, *said], said, strict=False))
    assert "\x1b" not in done.stderr  # plain lines, no live display's escapes


# ---- the reason a run was rejected -----------------------------------------------------------------------


@pytest.mark.slow
def test_runs_rejected_shows_why_each_run_was_rejected(tmp_path: Path) -> None:
    """A guided session's log: decay 1 failed a check and was rejected, decay 2 passed and the operator
    rejected it anyway; ``runs --verdict rejected`` on a real SQLite catalogue says both reasons."""
    from tankdaq.campaign.synthetic import SimulatedTest, write_simulated_campaign

    folder = tmp_path / "session"
    files = write_simulated_campaign(
        folder, ["swath"], "roll", [1.0], [8.0, 10.0], "mcap", test=SimulatedTest(duration_s=12.0)
    )
    log = SessionLog(folder)
    log.append("plan", plan={"name": "p"}, hull="swath", conditions=[])
    flagged = "release at 8.0 deg, asked 10 ± 1.5 deg"
    for decay, (path, reasons) in enumerate(zip(files, [[flagged], []], strict=True), 1):
        run = {"draft": "T", "angle_deg": 10.0, "file": path.name, "reasons": reasons, "measured": {}}
        log.append("run", decay=decay, **run)
        log.append("verdict", decay=decay, verdict="rejected", action="reject and repeat", reasons=reasons)
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    indexed = runner.invoke(app, ["catalogue", "index", str(folder), "--catalogue", url])
    assert indexed.exit_code == 0, indexed.output
    result = runner.invoke(app, ["runs", "--verdict", "rejected", "--catalogue", url])
    assert result.exit_code == 0, result.output
    header = next(line for line in result.stdout.splitlines() if "verdict" in line)
    assert "reason" in header, result.stdout
    text = " ".join(result.stdout.split())  # a folded cell read whole
    assert "2 run(s)" in result.output and flagged in text.replace("│ ", "").replace(" │", "")
    assert "the operator chose: reject and repeat" in text.replace("│ ", "").replace(" │", "")
