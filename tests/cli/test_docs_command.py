"""``tankdaq docs [TOPIC]`` and ``tankdaq.docs``: the pages ``--help`` cites, for whoever has tankdaq; the
example files copied out; long silent steps and ``decode`` saying where they are off a terminal."""

from __future__ import annotations

import itertools
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from typer.testing import CliRunner

import tankdaq
from tankdaq.cli import app
from tankdaq.cli.app import TerminalProgress
from tankdaq.cli.decode import decode_all
from tankdaq.errors import InputError
from tankdaq.heartbeat import heartbeat

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


@pytest.mark.slow
def test_docs_lists_every_page_and_prints_one_as_written() -> None:
    listed = runner.invoke(app, ["docs"])
    assert listed.exit_code == 0, listed.output
    names = [line.split()[0] for line in listed.stdout.splitlines()[:-1]]
    assert names == sorted(path.stem for path in (ROOT / "docs").glob("*.md"))
    assert "catalogue         The run catalogue" in listed.stdout
    shown = runner.invoke(app, ["docs", "catalogue"])
    assert shown.exit_code == 0
    assert shown.stdout == (ROOT / "docs" / "catalogue.md").read_text(encoding="utf-8") + "\n"
    assert tankdaq.docs("docs/models.md") == (ROOT / "docs" / "models.md").read_text(encoding="utf-8")


def test_an_unknown_topic_is_one_line_naming_the_topics() -> None:
    done = runner.invoke(app, ["docs", "catalog"])
    assert done.exit_code == 2 and "Traceback" not in done.output
    (line,) = done.stderr.strip().splitlines()
    assert "no docs page 'catalog'" in line and "catalogue, diagnose" in line and "notebook" in line
    with pytest.raises(InputError, match="the topics are api, architecture"):
        tankdaq.docs("nope")


def test_every_docs_page_cited_in_the_source_is_a_topic() -> None:
    """What ``--help`` and the docstrings cite as docs/X.md, ``tankdaq docs X`` prints."""
    cited = set()
    for path in (ROOT / "src" / "tankdaq").rglob("*.py"):
        cited |= {name for name in _cited(path.read_text(encoding="utf-8"))}
    topics = set(tankdaq.api.pages.topics())
    # pages other helpers add this round (lab-files, live-view) are cited before they land
    assert cited - topics <= {"lab-files", "live-view"}, cited - topics


def _cited(text: str) -> set[str]:
    import re

    return set(re.findall(r"docs/([a-z-]+)\.md", text))


@pytest.mark.slow
def test_examples_are_copied_into_a_new_folder_and_never_over_a_file(tmp_path: Path) -> None:
    done = runner.invoke(app, ["docs", "--examples", str(tmp_path / "ex")])
    assert done.exit_code == 0, done.output
    notebook = tmp_path / "ex" / "decay_in_a_notebook.ipynb"
    assert notebook.read_bytes() == (ROOT / "examples" / notebook.name).read_bytes()
    again = runner.invoke(app, ["docs", "--examples", str(tmp_path / "ex")])
    assert again.exit_code == 2 and "never writes over a file" in again.stderr


def test_a_heartbeat_says_where_a_silent_step_is_until_it_ends() -> None:
    said: list[str] = []
    two = threading.Event()

    def write(line: str) -> None:
        said.append(line)
        if len(said) == 2:
            two.set()

    with heartbeat("building native kernels", write, every_s=0.01):
        assert two.wait(30)  # the step: blocked until the heartbeat has spoken twice
    count = len(said)
    assert all(line.startswith("  still building native kernels (") and line.endswith(" s)") for line in said)
    assert len(said) == count  # nothing after the step ended


def test_the_heartbeat_command_runs_its_command_between_two_lines() -> None:
    command = [sys.executable, "-m", "tankdaq.heartbeat", "copying", sys.executable, "-c", "exit(3)"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 3
    first, last = done.stdout.splitlines()[0], done.stdout.splitlines()[-1]
    assert first == "copying ..." and last.startswith("copying: failed (exit 3) after ")


def test_decode_off_a_terminal_says_where_it_is_every_10_s(capsys: pytest.CaptureFixture[str]) -> None:
    data = (ROOT / "examples" / "capture.bin").read_bytes() * 400  # about 3 MiB: three pieces
    ticks = itertools.count(step=11.0)  # each reading of the clock 11 s later
    block = decode_all(data, TerminalProgress(clock=lambda: next(ticks)), "capture.bin")
    assert block.n_messages == 400 * 112
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("decoding capture.bin (KiB): 1024/") and " after 11 s" in lines[0]
    assert lines[-1].endswith(", done") and len(lines) >= 3
