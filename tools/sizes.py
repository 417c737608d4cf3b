"""The modules and functions past the size guideline, for a maintainer to look at (``make sizes``).

A room should fit in a head: about 500 lines a module, 80 a function body (from the first line after its
signature to its last: the docstring counts, a command's typer option signature does not), in
``src/tankdaq``, ``tests`` and ``bench`` alike. This is a guideline, not a gate: the report lists what is
over it, longest first, and exits 0. A module split only to pass a number is worse than one long module
that reads straight through.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
#: The code the guideline is for: the package, its tests and its benches.
SIZED = ("src/tankdaq", "tests", "bench")


def function_lengths(path: Path, root: Path = ROOT) -> dict[str, int]:
    """``{"src/tankdaq/room/module.py:Class.function": lines}`` for every function in one file."""
    where = path.relative_to(root).as_posix()
    lengths: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if not isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                visit(child, prefix)
                continue
            if not isinstance(child, ast.ClassDef):
                last = child.end_lineno or child.lineno
                lengths[f"{where}:{prefix}{child.name}"] = last - child.body[0].lineno + 1
            visit(child, f"{prefix}{child.name}.")

    visit(ast.parse(path.read_text(), str(path)), "")
    return lengths


def oversized(root: Path = ROOT, folders: tuple[str, ...] = SIZED) -> dict[str, int]:
    """Every module over ``MAX_MODULE_LINES`` and function over ``MAX_FUNCTION_LINES``, with its lines."""
    found: dict[str, int] = {}
    for path in sorted(path for folder in folders for path in (root / folder).rglob("*.py")):
        lines = len(path.read_text().splitlines())
        if lines > MAX_MODULE_LINES:
            found[path.relative_to(root).as_posix()] = lines
        found |= {name: n for name, n in function_lengths(path, root).items() if n > MAX_FUNCTION_LINES}
    return found


def main() -> int:
    found = oversized()
    print(
        f"size guideline: modules of at most about {MAX_MODULE_LINES} lines, function bodies of at most "
        f"about {MAX_FUNCTION_LINES} ({', '.join(SIZED)})"
    )
    if not found:
        print("nothing is over it")
        return 0
    modules = {name: n for name, n in found.items() if ":" not in name}
    functions = {name: n for name, n in found.items() if ":" in name}
    for title, group in (("modules", modules), ("functions", functions)):
        if group:
            print(f"{title} over it, longest first:")
            for name, n in sorted(group.items(), key=lambda item: (-item[1], item[0])):
                print(f"  {n:5d}  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
