"""The layer order in docs/architecture.md holds in the code: checked by reading every import in src/.

The table in the doc is the rule. Its rows are in layer order, and each row's "may import" column names
the tankdaq parts and the third-party libraries that package may use.
Imports inside functions count: a lazy import is still a dependency.
"""

from __future__ import annotations

import ast
import re
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src" / "tankdaq"
DOC = ROOT / "docs" / "architecture.md"

#: Third-party distributions whose use is a design decision (the rest of site-packages never appears).
THIRD_PARTY = {
    "numpy": "numpy",
    "scipy": "scipy",
    "numba": "numba",
    "mcap": "mcap",
    "rerun": "rerun-sdk",
    "matplotlib": "matplotlib",
    "serial": "pyserial",
    "typer": "typer",
    "rich": "rich",
    "pymoo": "pymoo",
    "distributed": "dask",
    "dask": "dask",
    "h5py": "h5py",
    "pyarrow": "pyarrow",
    "sqlalchemy": "sqlalchemy",
}
EVERYTHING = "everything"


def layer_table() -> dict[str, set[str]]:
    """``{part: allowed}`` in the doc's row order; part is "errors", "ident", ... (no "tankdaq." prefix)."""
    rows: dict[str, set[str]] = {}
    for line in DOC.read_text().splitlines():
        match = re.match(r"\| `tankdaq\.([a-z_]+)` \|.*\| ([^|]*) \|$", line)
        if match:
            allowed = {name.strip() for name in match.group(2).split(",") if name.strip() not in ("", "—")}
            rows[match.group(1)] = allowed
    return rows


def part_of(path: Path, root: Path = SRC) -> str:
    relative = path.relative_to(root)
    return relative.parts[0] if len(relative.parts) > 1 else relative.stem


def imports_of(path: Path, root: Path = SRC) -> set[str]:
    """Dotted names imported by one source file (relative imports resolved), lazy ones included."""
    package = ["tankdaq", *path.relative_to(root).parent.parts]
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join([*base, node.module] if node.module else base)
            names.add(module)
            if node.module is None:  # from . import name: the name is a module
                names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


def dependencies(path: Path, root: Path = SRC) -> set[str]:
    """What one file depends on, in the table's words: "ident", "store", "numpy", "rerun-sdk", ...

    A name from ``tankdaq/__init__`` (``__version__``) is no dependency.
    """
    found: set[str] = set()
    for name in imports_of(path, root):
        parts = name.split(".")
        if parts[0] == "tankdaq" and len(parts) > 1:
            if (SRC / parts[1]).is_dir() or (SRC / f"{parts[1]}.py").is_file():
                found.add(parts[1])
        elif parts[0] in THIRD_PARTY:
            found.add(THIRD_PARTY[parts[0]])
    return found


def allowed(dependency: str, own: str, rule: set[str]) -> bool:
    """A package uses itself freely; ``everything`` is the command line's rule."""
    return dependency == own or EVERYTHING in rule or dependency in rule


def test_the_doc_table_is_a_layer_order() -> None:
    """Each row may name only rows above it: the table itself has no cycle."""
    table = layer_table()
    assert {"errors", "xsens", "ident", "cli"} <= set(table), "the may-import table was not found in the doc"
    seen: list[str] = []
    for part, rule in table.items():
        upward = sorted(name for name in rule if name in table and name not in seen)
        assert not upward, f"tankdaq.{part} may import {upward}, which sit below it in the table"
        seen.append(part)


def test_every_part_of_src_has_a_row() -> None:
    table = layer_table()
    parts = {part_of(path) for path in SRC.rglob("*.py")} - {"__init__"}
    assert parts <= set(table), f"no row in docs/architecture.md for {sorted(parts - set(table))}"


@pytest.mark.parametrize("path", sorted(SRC.rglob("*.py")), ids=lambda p: str(p.relative_to(SRC)))
def test_imports_follow_the_table(path: Path) -> None:
    table = layer_table()
    own = part_of(path)
    if own == "__init__":
        return
    wrong = sorted(dep for dep in dependencies(path) if not allowed(dep, own, table[own]))
    rule = sorted(table[own])
    assert not wrong, (
        f"{path.relative_to(ROOT)} imports {wrong}; docs/architecture.md lets tankdaq.{own} use {rule}"
    )


def test_the_check_sees_a_lazy_upward_import(tmp_path: Path) -> None:
    """The analysis itself: imports inside a function, relative and absolute, are found and refused."""
    probe = tmp_path / "xsens" / "probe.py"
    probe.parent.mkdir()
    probe.write_text("import struct\n\ndef f():\n    from ..ident import kernels\n    import numba\n")
    found = dependencies(probe, root=tmp_path)
    assert found == {"ident", "numba"}
    refused = [dep for dep in sorted(found) if not allowed(dep, "xsens", {"errors", "numpy"})]
    assert refused == ["ident", "numba"]


def module_graph(root: Path = SRC) -> dict[str, set[str]]:
    """``{module: the tankdaq modules it imports}``, lazy imports included, packages by their ``__init__``."""
    modules: dict[str, Path] = {}
    for path in root.rglob("*.py"):
        parts = ("tankdaq", *path.relative_to(root).with_suffix("").parts)
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        targets = set()
        for imported in imports_of(path, root):
            parts = imported.split(".")
            while parts and ".".join(parts) not in modules:
                parts.pop()
            target = ".".join(parts)
            if target not in ("", "tankdaq", name):  # tankdaq/__init__ holds only the version
                targets.add(target)
        graph[name] = targets
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.append(member)
                    if member == node:
                        break
                if len(group) > 1:
                    cycles.append(sorted(group))
    return cycles


def test_no_import_cycle_between_modules() -> None:
    """Inside a room too: no module reaches, even lazily, a module that reaches back to it."""
    cycles = import_cycles(module_graph())
    assert not cycles, f"import cycles (lazy imports included): {cycles}"


def test_the_cycle_check_sees_a_lazy_cycle(tmp_path: Path) -> None:
    room = tmp_path / "ident"
    room.mkdir()
    (room / "__init__.py").write_text("")
    (room / "a.py").write_text("from .b import x\n")
    (room / "b.py").write_text("def f():\n    from . import c\n")
    (room / "c.py").write_text("import tankdaq.ident.a\n")
    (room / "d.py").write_text("from .a import x\n")
    expected = [["tankdaq.ident.a", "tankdaq.ident.b", "tankdaq.ident.c"]]
    assert import_cycles(module_graph(tmp_path)) == expected


def test_every_module_is_named_in_the_map() -> None:
    """docs/architecture.md's "Rooms" names every module, so the map cannot drift from the code."""
    rooms = DOC.read_text().split("\n## Rooms\n", 1)
    assert len(rooms) == 2, "no Rooms section in docs/architecture.md"
    named = set(re.findall(r"`(?:tankdaq\.)?([a-z_][a-z0-9_.]*)`", rooms[1]))
    missing = []
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        if module and module not in named:
            missing.append(module)
    assert not missing, f"modules docs/architecture.md's Rooms does not name: {missing}"


# ---- sizes: rooms that fit in a head -------------------------------------------------------------------

#: A module over this many lines, or a function whose body is over ``MAX_FUNCTION_LINES``, needs a reason
#: in docs/architecture.md's "Sizes" section.
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
#: The code the size rule holds for: the package, its tests and its benches.
SIZED = ("src/tankdaq", "tests", "bench")


def function_lengths(path: Path, root: Path = ROOT) -> dict[str, int]:
    """``{"src/tankdaq/room/module.py:Class.function": lines}`` for every function in one file.

    A function's lines run from the first line after its signature (the docstring counts) to its last:
    a command's typer option signature is no part of it, everything the function does is.
    """
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


def stated_size_exceptions() -> set[str]:
    """The modules and functions docs/architecture.md's "Sizes" section lets stay over the limits."""
    section = DOC.read_text().split("\n## Sizes\n", 1)
    assert len(section) == 2, "no Sizes section in docs/architecture.md"
    body = section[1].split("\n## ", 1)[0]
    return set(re.findall(r"^- `([\w/.]+\.py(?::[\w.]+)?)`", body, flags=re.MULTILINE))


def test_no_module_or_function_is_over_its_size_unless_the_map_says_why() -> None:
    unexplained = {name: n for name, n in oversized().items() if name not in stated_size_exceptions()}
    assert not unexplained, (
        f"over {MAX_MODULE_LINES} lines a module or {MAX_FUNCTION_LINES} a function body: {unexplained}; "
        "split it, or say why it must stay in docs/architecture.md's Sizes section"
    )


def test_every_size_exception_the_map_states_is_still_needed() -> None:
    """An exception that no longer applies is a stale line in the map: it goes."""
    stale = sorted(stated_size_exceptions() - set(oversized()))
    assert not stale, f"docs/architecture.md's Sizes section names what is within the limits now: {stale}"


def test_the_size_check_sees_a_long_function_and_not_a_long_signature(tmp_path: Path) -> None:
    room = tmp_path / "src" / "cli"
    room.mkdir(parents=True)
    options = "".join(f"    option_{i}: int = 0,\n" for i in range(60))
    body = "".join(f"x = {i}\n" for i in range(MAX_FUNCTION_LINES))
    (room / "command.py").write_text(
        f'def command(\n{options}) -> None:\n    """Help."""\n{textwrap.indent(body, " " * 4)}\n\n'
        f"class Kind:\n    def method(self) -> None:\n{textwrap.indent(body, ' ' * 8)}"
    )
    (room / "long.py").write_text("x = 0\n" * (MAX_MODULE_LINES + 1))
    assert function_lengths(room / "command.py", tmp_path) == {
        "src/cli/command.py:command": MAX_FUNCTION_LINES + 1,  # its docstring and body, not the 60 options
        "src/cli/command.py:Kind.method": MAX_FUNCTION_LINES,
    }
    long_ones = {"src/cli/command.py:command": MAX_FUNCTION_LINES + 1, "src/cli/long.py": 501}
    assert oversized(tmp_path, ("src",)) == long_ones
