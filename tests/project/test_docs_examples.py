"""A clone, ``make demo``, then every example of the README and the docs as written (issue 42).

One module-scoped clone of this checkout's committed HEAD. Its ``.venv`` is made as ``make demo``'s
install step leaves it, from the environment already built (issue 43: the CI's own ``make test`` on a
fresh clone proves a fresh install; here it cost two minutes): a venv of its own with pip, the clone
installed editable into it, the dependencies through a ``.pth`` line to this environment's
site-packages, the user kernels reused through ``TANKDAQ_KERNEL_DIR``. ``make demo`` then runs for
real, its output read line by line from the pipe as it arrives. What the install step installs is
checked without installing: ``make -n demo`` on a clone without ``.venv`` (the runtime alone, under
the heartbeat) and the installed metadata (no test tool among what tankdaq needs to run). Then, with
that ``.venv`` active and a fresh home folder, every fenced example of README.md and docs/*.md in
reading order (tests/support/doc_examples.py says how a fence and a marker say what to expect). The pages'
structure is checked without the clone.
"""

from __future__ import annotations

import itertools
import os
import re
import subprocess
import sys
import sysconfig
import time
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

from support.doc_examples import (
    READ_ONLY,
    Example,
    blocks,
    examples,
    in_a_clone,
    pages,
    problem,
    run,
    shell_env,
)
from tankdaq.ident.compiled import kernel_folder

ROOT = Path(__file__).resolve().parents[2]
#: make demo never goes quiet for longer than this (s) while it installs and prepares.
QUIET_S = 10.0
#: The test toolchain: none of it in the demo's environment.
TEST_TOOLS = ("pytest", "mypy", "ruff")


def test_every_fence_says_what_it_holds_and_no_command_hides_in_a_text_block() -> None:
    found = examples(ROOT)  # raises on a fence without a known info string
    assert {e.page for e in found} >= {"README.md", "docs/api.md", "docs/pypi.md", "docs/catalogue.md"}
    for path in pages(ROOT):
        for info, line, body in blocks(path):
            if info not in READ_ONLY:
                continue
            answered = re.search(r"^> ", body, re.M) is not None  # an operator's transcript: read
            for text in body.splitlines():
                command = re.match(r"\s*(\$ )?tankdaq \S+.*", text)
                if command is None or (command.group(1) and answered):
                    continue
                assert re.search(r"\b[A-Z]{2,}\b|\[", text), (
                    f"{path.name}:{line}: a command in a text block: {text}"
                )


def test_no_example_names_a_file_nobody_has() -> None:
    """The files the issue found dead are gone from every runnable example."""
    dead = ("kvlcc2.csv", "run21338.h5", "my_code.csv", "capture.bin", "model_test_21338.csv", "runs.h5")
    named = re.compile(rf"(?<![\w/])({'|'.join(map(re.escape, dead))})")  # not examples/capture.bin
    runnable = [e for e in examples(ROOT) if e.kind in ("sh", "python")]
    assert not [str(e) for e in runnable if named.search(e.text)]
    api = next(e for e in runnable if e.page == "docs/api.md")
    assert 'angle_col="roll_deg"' not in api.text  # rec.to_csv writes roll_rad


def _make_demo(clone: Path, env: dict[str, str]) -> tuple[int, list[tuple[float, str]]]:
    """``make demo`` in ``clone``: its exit code and every output line with the time it arrived."""
    process = subprocess.Popen(
        ["make", "demo"], cwd=clone, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    arrived = [(time.monotonic(), "(make demo started)")]
    assert process.stdout is not None
    for line in process.stdout:  # one event per line, as the pipe delivers it
        arrived.append((time.monotonic(), line.rstrip("\n")))
    arrived.append((time.monotonic(), "(make demo ended)"))
    return process.wait(), arrived


def _venv_from_this_one(clone: Path) -> None:
    """``clone``'s ``.venv`` as ``make demo``'s install step leaves it, from the environment already
    built: its own python and pip; the clone installed editable as pip does it (a ``.pth`` line to its
    ``src``, read first, and a launcher for each of pyproject's scripts); the dependencies through a
    ``.pth`` line to this environment's site-packages (a nested ``.pth`` is not processed: this
    checkout's own editable install stays out); and the install step's stamp, so ``make demo`` goes on
    to its work."""
    venv = clone / ".venv"
    subprocess.run([sys.executable, "-m", "venv", venv], check=True, timeout=300)
    python = venv / "bin" / "python"
    site = Path(
        subprocess.run(
            [python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
            capture_output=True, text=True, check=True, timeout=60,
        ).stdout.strip()
    )  # fmt: skip
    (site / "__editable__tankdaq.pth").write_text(f"{clone / 'src'}\n")
    (site / "_project_dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")
    scripts = tomllib.loads((clone / "pyproject.toml").read_text())["project"]["scripts"]
    for name, target in scripts.items():
        module, function = target.split(":")
        launcher = venv / "bin" / name
        launcher.write_text(
            f"#!{python}\nimport sys\nfrom {module} import {function}\nsys.exit({function}())\n"
        )
        launcher.chmod(0o755)
    (venv / ".installed").touch()  # make's STAMP, newer than pyproject.toml


@pytest.fixture(scope="module")
def clone(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str], list[tuple[float, str]]]:
    """A clone of HEAD where ``make demo`` ran: the folder, the active shell's environment, make's lines."""
    folder = tmp_path_factory.mktemp("fresh") / "tankdaq"
    subprocess.run(["git", "clone", "-q", ROOT, folder], check=True, timeout=120)
    home = folder.parent / "home"
    home.mkdir()
    _venv_from_this_one(folder)
    env = shell_env(folder / ".venv", home) | {"TANKDAQ_KERNEL_DIR": str(kernel_folder())}
    without_venv = {**env, "PATH": env["PATH"].split(os.pathsep, 1)[1]}  # before make demo: not active
    without_venv.pop("VIRTUAL_ENV")
    code, arrived = _make_demo(folder, without_venv)
    assert code == 0, "\n".join(line for _, line in arrived[-40:])
    return folder, env, arrived


def _needed_to_run(name: str = "tankdaq") -> set[str]:
    """Every distribution ``name`` needs to run (its requirements but its extras', and theirs), from the
    installed metadata: what ``pip install -e .`` installs."""
    found: set[str] = set()
    todo = [name]
    while todo:
        try:
            requires = metadata.requires(todo.pop()) or []
        except metadata.PackageNotFoundError:
            continue  # a requirement for another platform or Python
        for line in requires:
            if re.search(r";.*\bextra\s*==", line):
                continue
            needed = re.split(r"[\s;\[<>=!~(]", line, maxsplit=1)[0].lower().replace("_", "-")
            if needed not in found:
                found.add(needed)
                todo.append(needed)
    return found


@pytest.mark.slow
def test_make_demo_installs_what_tankdaq_needs_to_run_under_the_heartbeat_and_no_test_tool(
    tmp_path: Path,
) -> None:
    folder = tmp_path / "tankdaq"
    subprocess.run(["git", "clone", "-q", ROOT, folder], check=True, timeout=120)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("MAKEFLAGS", "MFLAGS", "MAKELEVEL"))}
    planned = subprocess.run(["make", "-n", "demo"], cwd=folder, env=env, capture_output=True, text=True)
    assert planned.returncode == 0, planned.stderr
    steps = planned.stdout.replace("\\\n", " ").splitlines()  # a step continued over lines: one
    (install,) = [line for line in steps if " pip install " in line and " -e " in line]
    assert "tankdaq.heartbeat" in install and "installing tankdaq and what it needs to run" in install
    assert re.search(r" -e \.$", install), install  # the runtime alone: no [test] extra
    needed = _needed_to_run()
    assert {"numpy", "mcap", "typer"} <= needed, needed  # the metadata is read
    assert not needed & set(TEST_TOOLS), needed & set(TEST_TOOLS)


@pytest.mark.slow
@pytest.mark.timeout(1800)  # the fixture's make demo: its kernels checked, then the demo
def test_make_demo_says_something_every_10_s_and_ends_with_the_way_in(clone) -> None:
    folder, _, arrived = clone
    gaps = [(later - earlier, line) for (earlier, _), (later, line) in itertools.pairwise(arrived)]
    assert max(gap for gap, _ in gaps) <= QUIET_S, max(gaps)
    said = "\n".join(line for _, line in arrived)
    assert ". .venv/bin/activate" in said  # the way in, at the end
    scripts = {path.name for path in (folder / ".venv" / "bin").iterdir()}
    assert "tankdaq" in scripts and not scripts & set(TEST_TOOLS), scripts & set(TEST_TOOLS)


@pytest.mark.slow
@pytest.mark.timeout(3600)  # about a hundred commands, a few of them fits of a minute
def test_every_example_runs_as_written_after_make_demo(clone) -> None:
    folder, env, _ = clone
    ran: list[Example] = []
    wrong: list[str] = []
    for example in in_a_clone(folder):  # docs/pypi.md: tests/project/test_wheel.py, from the wheel
        if example.kind == "make":
            assert example.text in ("make demo", "make test"), example  # the fixture ran the first
            continue
        if example.kind == "." or example.marker in ("[on the server]", "[long]"):
            continue  # the active environment is this shell's; the server's and the long ones: below
        outcome = run(example, folder, env)
        ran.append(example)
        said = problem(example, outcome)
        if said is not None:
            wrong.append(said)
    assert not wrong, "\n\n".join(wrong)
    assert {e.marker for e in ran} >= {None, "[hardware]", "[server]", "[Ctrl-C]"}
    assert sum(e.kind == "python" for e in ran) >= 5 and len(ran) >= 80, len(ran)
