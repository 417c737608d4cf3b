"""Every fenced example of README.md and docs/*.md, found and run as written
(tests/project/test_docs_examples.py).

A fence says what its block is: ``sh`` (commands, one a line, run in order), ``console`` (a transcript:
the lines after ``$ `` are commands, the rest is output), ``python`` (run: the blocks of one page in one
interpreter, in order, as a notebook would), ``toml``, ``json``, ``text`` (files, output and synopses:
read, not run). A command's comment may mark it: ``[hardware]`` (needs the MTi-G: here it must fail with
its one-line error), ``[server]`` (needs a lab's PostgreSQL server: the same), ``[Ctrl-C]`` (runs until
stopped: it must start, print its first line and stop cleanly on SIGINT), ``[on the server]`` (an
administrator's step on the PostgreSQL server: not run here), ``[long]`` (the seeds' own GA at their
sizes, seconds to minutes each: not run by the test). ``make demo`` is what the
clone ran first; ``pip install`` lines are resolved (``--dry-run --no-deps``), not installed over the
environment the other examples use; they and ``pip wheel`` build with the test extra's hatchling
(``--no-build-isolation``: no download of the build backend for each line). A Python line followed by
a ``# SomeError: message`` comment must raise that error with that message (up to a ``...``).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

#: Fence info strings: what runs, what is read only.
RUN = ("sh", "console", "python")
READ_ONLY = ("toml", "json", "text")
MARKERS = ("[hardware]", "[server]", "[Ctrl-C]", "[on the server]", "[long]")
#: A command's trailing comment: two spaces or more, then ``#``.
COMMENT = re.compile(r"\s{2,}#\s?|\s#\s")
FENCE = re.compile(r"^ *```([\w-]*)[^\n]*\n(.*?)^ *```", re.S | re.M)  # also a list item's, indented


@dataclass(frozen=True)
class Example:
    """One command line or one page's Python, where it is written and how it must end."""

    page: str
    line: int
    kind: str  # "sh", "python", "make", "pip"
    text: str
    marker: str | None = None

    def __str__(self) -> str:
        return f"{self.page}:{self.line}: {self.text.splitlines()[0][:100]}"


def pages(root: Path) -> list[Path]:
    """README.md, then every docs page in name order: the order a reader follows and the test runs."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def blocks(path: Path) -> list[tuple[str, int, str]]:
    """(info string, line of the fence, text) of every fenced block of a Markdown page."""
    text = path.read_text(encoding="utf-8")
    return [(m.group(1), text.count("\n", 0, m.start()) + 1, m.group(2)) for m in FENCE.finditer(text)]


def _commands(body: str, transcript: bool) -> list[tuple[int, str]]:
    """(line offset, command with its comment) of a block; ``\\`` continues a line; a transcript's
    commands are its ``$ `` lines."""
    found: list[tuple[int, str]] = []
    lines = body.splitlines()
    index = 0
    while index < len(lines):
        start, line = index, lines[index]
        index += 1
        if transcript and not line.startswith("$ "):
            continue
        line = line.removeprefix("$ ") if transcript else line
        while line.rstrip().endswith("\\") and index < len(lines):
            line = line.rstrip()[:-1] + " " + lines[index].strip()
            index += 1
        if line.strip() and not line.lstrip().startswith("#"):
            found.append((start + 1, line.strip()))
    return found


def examples(root: Path) -> list[Example]:
    """Every example, in reading order; a page's Python joined into one example at its first block."""
    found: list[Example] = []
    for path in pages(root):
        page = str(path.relative_to(root))
        python: list[tuple[int, str]] = []
        for info, line, body in blocks(path):
            if info not in RUN + READ_ONLY:
                raise ValueError(f"{page}:{line}: a fence says what it holds: one of {RUN + READ_ONLY}")
            if info == "python":
                python.append((line, body))
                continue
            if info not in RUN:
                continue
            for offset, command in _commands(body, transcript=info == "console"):
                found.append(_command(page, line + offset, command))
        if python:
            code = "\n".join(f"# {page}:{line}\n{_raises(body)}" for line, body in python)
            found.append(Example(page, python[0][0], "python", code))
    return found


def _command(page: str, line: int, written: str) -> Example:
    parts = COMMENT.split(written, maxsplit=1)
    command, comment = parts[0].strip(), parts[1] if len(parts) > 1 else ""
    marker = next((m for m in MARKERS if m in comment), None)
    kind = command.split()[0] if command.split()[0] in ("make", "pip", ".") else "sh"
    return Example(page, line, kind, command, marker)


def _raises(body: str) -> str:
    """A block's Python with each line followed by ``# SomeError: message`` made into a check that it
    raises that error with that message."""
    out: list[str] = []
    lines = body.splitlines()
    for index, line in enumerate(lines):
        said = re.match(r"# (\w+Error): (.*)", lines[index + 1]) if index + 1 < len(lines) else None
        if said is None:
            out.append(line)
            continue
        expected = f"{said.group(1)}: {said.group(2).split('...')[0]}"
        out += [
            "try:",
            f"    {line}",
            "except Exception as exc:",
            "    shown = f'{type(exc).__name__}: {exc}'",
            f"    assert shown.startswith({expected!r}), shown",
            "else:",
            f"    raise AssertionError({line!r} + ' did not raise')",
        ]
    return "\n".join(out)


@dataclass(frozen=True)
class Outcome:
    """How an example ended: its exit code, stdout and stderr."""

    code: int
    out: str
    err: str


def run(example: Example, cwd: Path, env: dict[str, str], timeout_s: float = 600) -> Outcome:
    """Run one example in ``cwd`` as a user's shell would (``bash -c``: globs, quotes)."""
    if example.kind == "python":
        script = cwd / ".doc_example.py"
        script.write_text(example.text)
        done = subprocess.run(
            ["python", script.name], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout_s
        )
        script.unlink()
        return Outcome(done.returncode, done.stdout, done.stderr)
    command = example.text
    if example.kind == "pip":  # the build backend from the test extra: no download per line
        command = command.replace("pip install", "pip install --dry-run --no-deps", 1)
        command = re.sub(r"^pip (install|wheel)", r"pip \1 --no-build-isolation", command)
    if example.marker == "[Ctrl-C]":
        return _until_stopped(command, cwd, env, timeout_s)
    done = subprocess.run(
        ["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout_s
    )
    return Outcome(done.returncode, done.stdout, done.stderr)


def _until_stopped(command: str, cwd: Path, env: dict[str, str], timeout_s: float) -> Outcome:
    """Start a command that runs until Ctrl-C, wait for its first line on stdout, then send SIGINT."""
    process = subprocess.Popen(
        ["bash", "-c", f"exec {command}"],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        first = process.stdout.readline() if process.stdout else ""  # blocks until it says where it is
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=timeout_s)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return Outcome(process.returncode, first + out, err)


def problem(example: Example, outcome: Outcome) -> str | None:
    """What is wrong with how an example ended (None: it ended as its page says it does)."""
    said = f"{example}\nexit {outcome.code}\nstdout: {outcome.out[-1500:]}\nstderr: {outcome.err[-3000:]}"
    if "Traceback" in outcome.err:
        return f"a traceback: {said}"
    if example.marker in ("[hardware]", "[server]"):
        lines = [line for line in outcome.err.splitlines() if line.strip()]
        if outcome.code not in (1, 2) or len(lines) != 1:
            return f"not its one-line error ({example.marker}): {said}"
        return None
    if example.marker == "[Ctrl-C]":
        return None if outcome.code in (0, 130, -signal.SIGINT) else f"not stopped cleanly: {said}"
    return None if outcome.code == 0 else f"failed: {said}"


def shell_env(venv: Path, home: Path) -> dict[str, str]:
    """The environment of a shell where ``venv`` is active (``. .venv/bin/activate``), with ``home``."""
    steering = ("TANKDAQ_", "PYTHON", "VIRTUAL_ENV", "MAKEFLAGS", "MFLAGS", "MAKELEVEL")  # make test's too
    keep = {k: v for k, v in os.environ.items() if not k.startswith(steering)}
    path = [str(venv / "bin"), *(p for p in keep.get("PATH", "").split(os.pathsep) if p)]
    return keep | {"PATH": os.pathsep.join(path), "VIRTUAL_ENV": str(venv), "HOME": str(home)}


#: A pip user's page: run by tests/project/test_wheel.py in a folder of their own, after the wheel is
# installed.
PIP_PAGE = "docs/pypi.md"


def in_a_clone(root: Path) -> list[Example]:
    """The examples a fresh clone runs after ``make demo``, in order: every page's but the pip user's."""
    return [e for e in examples(root) if e.page != PIP_PAGE]


def main(root: Path, cwd: Path) -> int:
    """Run every example of ``root``'s pages in ``cwd`` with its ``.venv`` active; print what failed."""
    env = shell_env(cwd / ".venv", Path(os.environ.get("DOCS_HOME", cwd / "home")))
    failed = 0
    for example in in_a_clone(root):
        if example.kind in ("make", ".") or example.marker in ("[on the server]", "[long]"):
            continue
        outcome = run(example, cwd, env)
        wrong = problem(example, outcome)
        print(("FAIL " + wrong) if wrong else f"ok   {example}", flush=True)
        failed += wrong is not None
    return failed


if __name__ == "__main__":  # python tests/support/doc_examples.py ROOT CLONE: the pages of ROOT run in CLONE
    sys.exit(min(main(Path(sys.argv[1]), Path(sys.argv[2])), 1))
