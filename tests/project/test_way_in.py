"""The way in after ``make demo``: the demo ends by saying how to run ``tankdaq`` (its environment is not
active) and the next commands on its files; the README says the same right after ``make demo``, and its
commands, run as written after two demos, work on the demo's files (no "same decay" from the second)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tankdaq.cli.way_in import way_in

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = Path(sys.executable).parent  # this venv's bin: the one a make demo would leave inactive
DEMO = [".venv/bin/tankdaq", "demo", "--runs", "1", "--sim-speed", "20"]  # make demo's, one short decay


def _without_venv() -> dict[str, str]:
    """The environment of a shell where the venv is not active (make demo's, after it returns)."""
    path = [p for p in os.environ["PATH"].split(os.pathsep) if p and Path(p) != SCRIPTS]
    return {**os.environ, "PATH": os.pathsep.join(path)}


def _fenced(text: str) -> list[list[str]]:
    """Every fenced block of a Markdown text, its lines."""
    return [block.strip("\n").splitlines() for block in re.findall(r"```\w*\n(.*?)```", text, re.S)]


def _readme_after_demo() -> tuple[str, list[str]]:
    """The README's text from the ``make demo`` block to the next heading, and the block after make demo's."""
    readme = (ROOT / "README.md").read_text()
    start = readme.index("make demo ")
    blocks = _fenced(readme)
    demo = next(i for i, block in enumerate(blocks) if block[0].startswith("make demo "))
    return readme[start : readme.index("\n#", start)], blocks[demo + 1]


@pytest.fixture(scope="module")
def two_demos(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A folder with ``.venv`` (this venv) where the demo ran twice, as ``make demo`` runs it; the
    second run's stdout."""
    folder = tmp_path_factory.mktemp("clone")
    (folder / ".venv").symlink_to(SCRIPTS.parent, target_is_directory=True)
    said = ""
    for _ in range(2):
        done = subprocess.run(
            DEMO, cwd=folder, env=_without_venv(), capture_output=True, text=True, timeout=300
        )
        assert done.returncode == 0, done.stderr
        said = done.stdout
    return folder, said


def test_the_way_in_is_the_shells_tankdaq_or_the_scripts_path(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)  # outside the venv's folder: its path is said whole
    monkeypatch.setenv("PATH", f"{SCRIPTS}{os.pathsep}{_without_venv()['PATH']}")
    assert way_in() == ("tankdaq", None)  # the venv active (its bin on PATH): tankdaq alone
    monkeypatch.setenv("PATH", _without_venv()["PATH"])
    command, how = way_in()
    assert command == str(SCRIPTS / "tankdaq")
    assert how is not None and f". {SCRIPTS / 'activate'}" in how and command in how


@pytest.mark.slow
def test_the_demo_ends_with_the_readmes_way_in_and_its_commands_run_as_written(two_demos) -> None:
    folder, said = two_demos
    command = str(SCRIPTS / "tankdaq")
    text, block = _readme_after_demo()
    assert ". .venv/bin/activate" in text and ".venv/bin/tankdaq" in text  # said right after make demo
    assert block[0].startswith(". .venv/bin/activate")
    last = said.strip().splitlines()
    assert f". {SCRIPTS / 'activate'}" in last[-4]  # the demo's way in: its venv is not active
    commands = [line.split("#")[0].strip() for line in block[1:]]
    assert [line.strip() for line in last[-2:]] == [c.replace("tankdaq", command, 1) for c in commands]
    script = "\n".join(["set -e", *block])  # the README's block as written, in the folder of the demos
    done = subprocess.run(
        ["bash", "-c", script], cwd=folder, env=_without_venv(), capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert "one decay from two files" not in done.stderr + done.stdout  # the second demo's decays are new
    assert len(list((folder / "recordings" / "demo").glob("*.mcap"))) == 2
    assert done.stdout.count(".mcap: release") == 2  # replay played both


@pytest.mark.parametrize("page", ["README.md", "docs/pypi.md"])
def test_the_commands_after_the_demo_read_its_folder(page: str) -> None:
    """Every command that reads recordings in the page's blocks names the demo's folder, where they are."""
    lines = [line for block in _fenced((ROOT / page).read_text()) for line in block]
    reading = [
        line
        for line in lines
        if re.match(r"tankdaq (identify|replay|export|campaign|diagnose) recordings/", line)
    ]
    assert reading
    assert all(" recordings/demo/" in line for line in reading), [
        line for line in reading if " recordings/demo/" not in line
    ]
