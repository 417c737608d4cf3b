"""Mark every test over a threshold ``slow`` from pytest's durations: ``python tools/mark_slow.py . LOG...``.

``make check`` runs the tests not marked slow and must stay under a minute on a 2-core machine: when it
grows, run the whole suite with ``--durations=0`` into LOG and mark from it.

LOG is the output of a pytest run with ``--durations=0`` (``make test`` prints every phase over 5 s:
``--durations=0 --durations-min=5``); lines ``12.34s call     tests/room/test_x.py::test_name[param]``.
A test's setup, call and teardown are added up (a module fixture's setup counts on the test that made it:
the other tests of that fixture are marked too, since ``make check`` would pay for it on whichever runs
first). ``--over S`` (default 0.5) is the threshold: a test's parametrized cases count together. A
function already marked slow (or in a module or class marked slow) is left alone; the mark goes right
above ``def``. Re-runnable: prints what it marked.
"""

from __future__ import annotations

import ast
import math
import os
import re
import sys
from collections import defaultdict
from pathlib import Path

LINE = re.compile(r"^\s*([\d.]+)s (setup|call|teardown)\s+(\S+?\.py)::(\S+)")


def durations(logs: list[Path]) -> dict[tuple[str, str], tuple[float, float]]:
    """(file, test function or Class::method without parameters) -> (the longest total, the longest
    setup) seen in any log."""
    longest: dict[tuple[str, str], tuple[float, float]] = {}
    for log in logs:
        total: dict[tuple[str, str], float] = defaultdict(float)
        setup: dict[tuple[str, str], float] = defaultdict(float)
        for line in log.read_text(errors="replace").splitlines():
            found = LINE.match(line)
            if found:
                key = (found[3], found[4].split("[", 1)[0])
                total[key] += float(found[1])
                if found[2] == "setup":
                    setup[key] = max(setup[key], float(found[1]))
        for key, seconds in total.items():
            was = longest.get(key, (0.0, 0.0))
            longest[key] = (max(was[0], seconds), max(was[1], setup[key]))
    return longest


def _is_slow(decorators: list[ast.expr]) -> bool:
    return any("mark.slow" in ast.unparse(d) for d in decorators)


def _fixture_users(tree: ast.Module, test: str) -> set[str]:
    """The tests of a module that take a module- or session-scoped fixture ``test`` takes."""
    scoped = {
        node.name
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef)
        and any("fixture" in ast.unparse(d) and re.search(r"scope=.(module|session|package)", ast.unparse(d))
                for d in node.decorator_list)
    }  # fmt: skip
    arguments = {
        node.name: {a.arg for a in node.args.args}
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef) and node.name.startswith("test")
    }
    shared = arguments.get(test, set()) & scoped
    return {name for name, args in arguments.items() if args & shared}


def mark(root: Path, slow: dict[str, set[str]], by_setup: dict[str, set[str]]) -> list[str]:
    marked: list[str] = []
    for file in sorted({*slow, *by_setup}):
        names = slow.get(file, set())
        path = root / file
        if not path.is_file():
            print(f"mark_slow: {file} is not here (moved or renamed since the run?)", file=sys.stderr)
            continue
        text = path.read_text()
        tree = ast.parse(text)
        if any(isinstance(n, ast.Assign) and "pytestmark" in ast.unparse(n) and "slow" in ast.unparse(n)
               for n in tree.body):  # fmt: skip
            continue
        wanted = {name.split("::")[-1] for name in names}
        for name in by_setup.get(file, set()):  # its module fixture is the long part: every user pays it
            wanted |= _fixture_users(tree, name.split("::")[-1])
        lines = text.splitlines(keepends=True)
        inserts: list[tuple[int, str]] = []
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and _is_slow(node.decorator_list):
                for child in node.body:
                    if isinstance(child, ast.FunctionDef):
                        wanted.discard(child.name)
        for node in ast.walk(tree):
            if not isinstance(node, ast.FunctionDef) or node.name not in wanted:
                continue
            if not _is_slow(node.decorator_list):
                indent = lines[node.lineno - 1][: node.col_offset]
                inserts.append((node.lineno - 1, f"{indent}@pytest.mark.slow\n"))
                marked.append(f"{file}::{node.name}")
        for index, line in sorted(inserts, reverse=True):
            lines.insert(index, line)
        if inserts:
            new = "".join(lines)
            if not re.search(r"^import pytest$", new, re.M):
                future = r"^(from __future__ import annotations\n)"
                new = re.sub(future, r"\1\nimport pytest\n", new, count=1, flags=re.M)
            temporary = path.with_name(f".{path.name}.mark_slow.tmp")
            temporary.write_text(new)
            os.replace(temporary, path)  # a test file is never left half-written
    return marked


def main(argv: list[str]) -> int:
    over = 0.5
    if "--over" in argv:
        at = argv.index("--over")
        try:
            over = float(argv[at + 1])
        except (IndexError, ValueError):
            over = math.nan
        if not math.isfinite(over) or over < 0:
            print("mark_slow: --over takes seconds, a number >= 0 (e.g. --over 0.5)", file=sys.stderr)
            return 2
        del argv[at : at + 2]
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    root, logs = Path(argv[0]), [Path(a) for a in argv[1:]]
    missing = [str(log) for log in logs if not log.is_file()]
    if not root.is_dir() or missing:
        print(
            f"mark_slow: no such folder or log: {root if not root.is_dir() else ', '.join(missing)}",
            file=sys.stderr,
        )
        return 2
    slow: dict[str, set[str]] = defaultdict(set)
    by_setup: dict[str, set[str]] = defaultdict(set)
    for (file, name), (seconds, setup) in durations(logs).items():
        if seconds > over:
            slow[file].add(name)
        if setup > over:
            by_setup[file].add(name)
    for line in mark(root, slow, by_setup):
        print(f"mark_slow: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
