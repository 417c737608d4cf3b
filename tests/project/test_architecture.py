"""The layer rules in layers.toml hold in the code: checked by reading every import in src/.

layers.toml's ``[rooms]`` is in layer order, and each room names the tankdaq rooms and the third-party
libraries (``[libraries]``) it may use. Imports inside functions count: a lazy import is still a
dependency. No module imports another that reaches back to it, and none imports ``tankdaq/__init__``
(which loads the public API) for anything: ``__version__`` is ``tankdaq._version``'s.
"""

from __future__ import annotations

import ast
import importlib.util
import textwrap
import tomllib
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src" / "tankdaq"
LAYERS = ROOT / "layers.toml"
EVERYTHING = "everything"


def layer_rules(path: Path = LAYERS) -> tuple[dict[str, set[str]], dict[str, str]]:
    """``({room: allowed}`` in layer order, ``{import name: library})`` from layers.toml."""
    rules = tomllib.loads(path.read_text())
    return {room: set(allowed) for room, allowed in rules["rooms"].items()}, dict(rules["libraries"])


def layer_table() -> dict[str, set[str]]:
    return layer_rules()[0]


THIRD_PARTY = layer_rules()[1]


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
    """What one file depends on, in layers.toml's words: "ident", "store", "numpy", "rerun-sdk", ..."""
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


def rule_problems(table: dict[str, set[str]], libraries: dict[str, str]) -> list[str]:
    """What is wrong with a set of layer rules: a room that may import one below it, or a name that is
    neither a room nor a library (a typo is no rule)."""
    problems: list[str] = []
    seen: list[str] = []
    for part, rule in table.items():
        upward = sorted(name for name in rule if name in table and name not in seen)
        if upward:
            problems.append(f"tankdaq.{part} may import {upward}, which sit below it")
        unknown = sorted(rule - set(table) - set(libraries.values()) - {EVERYTHING})
        if unknown:
            problems.append(f"tankdaq.{part} may use {unknown}: no such room or library")
        seen.append(part)
    return problems


def test_the_rules_are_a_layer_order() -> None:
    """Each room may name only rooms above it: the rules themselves have no cycle."""
    table, libraries = layer_rules()
    assert {"errors", "xsens", "ident", "session", "cli"} <= set(table), "layers.toml lost its rooms"
    assert not rule_problems(table, libraries), f"layers.toml: {rule_problems(table, libraries)}"


def test_the_rule_check_sees_an_upward_rule_and_a_typo(tmp_path: Path) -> None:
    rules = tmp_path / "layers.toml"
    rules.write_text(
        '[rooms]\nerrors = []\nxsens = ["errors", "ident", "nunpy"]\nident = ["xsens", "numpy"]\n'
        '[libraries]\nnumpy = "numpy"\n'
    )
    table, libraries = layer_rules(rules)
    assert list(table) == ["errors", "xsens", "ident"]  # the file's order is the layer order
    assert rule_problems(table, libraries) == [
        "tankdaq.xsens may import ['ident'], which sit below it",
        "tankdaq.xsens may use ['nunpy']: no such room or library",
    ]


def test_every_part_of_src_has_a_row() -> None:
    table = layer_table()
    parts = {part_of(path) for path in SRC.rglob("*.py")} - {"__init__"}
    assert parts <= set(table), f"no room in layers.toml for {sorted(parts - set(table))}"


@pytest.mark.slow
def test_the_session_sits_above_the_api_and_acquisition() -> None:
    """The guided session drives a recording and reports through the public API: nothing below it
    (the API, acquisition and what they use) may reach it."""
    order = list(layer_table())
    assert order.index("api") < order.index("session") and order.index("acquire") < order.index("session")
    below = order[: order.index("session")]
    reaching = sorted(
        path.relative_to(ROOT).as_posix()
        for path in SRC.rglob("*.py")
        if part_of(path) in below and "session" in dependencies(path)
    )
    assert not reaching, f"below the session, these import it: {reaching}"


@pytest.mark.slow
def test_no_module_imports_the_package_root() -> None:
    """``tankdaq/__init__`` loads the public API on first use: a room that imported a name from it
    (``from .. import __version__``) would sit below the API and on top of it at once."""
    rooms = set(module_graph())  # every module and package: ``from .. import room`` names a room
    wrong = []
    for path in sorted(SRC.rglob("*.py")):
        if path == SRC / "__init__.py":
            continue
        package = ["tankdaq", *path.relative_to(SRC).parent.parts]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                base = package[: len(package) - node.level + 1] if node.level else []
                module = ".".join([*base, node.module] if node.module else base)
                if module == "tankdaq":
                    names = [f"tankdaq.{alias.name}" for alias in node.names]
                    wrong += [f"{path.relative_to(ROOT)}: {name}" for name in names if name not in rooms]
    assert not wrong, f"imported from tankdaq/__init__: {wrong}"


@pytest.mark.parametrize("path", sorted(SRC.rglob("*.py")), ids=lambda p: str(p.relative_to(SRC)))
@pytest.mark.slow
def test_imports_follow_the_table(path: Path) -> None:
    table = layer_table()
    own = part_of(path)
    if own == "__init__":
        return
    wrong = sorted(dep for dep in dependencies(path) if not allowed(dep, own, table[own]))
    rule = sorted(table[own])
    assert not wrong, f"{path.relative_to(ROOT)} imports {wrong}; layers.toml lets tankdaq.{own} use {rule}"


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
            if target not in ("", "tankdaq", name):  # ``from .. import room``: the room, not the root
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_no_two_public_classes_share_a_name() -> None:
    """A class name says which class it is: ``Decay`` in one room and ``Decay`` in another made readers
    (and imports) guess. Nested classes count; a leading underscore is private."""
    where: dict[str, list[str]] = {}
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                where.setdefault(node.name, []).append(path.relative_to(SRC).as_posix())
    shared = {name: paths for name, paths in where.items() if len(paths) > 1}
    assert not shared, f"public classes sharing a name: {shared}"


# ---- sizes: a guideline, reported by `make sizes` (tools/sizes.py), never a failure ------------------


def load_sizes() -> types.ModuleType:
    """tools/sizes.py, loaded from its path (tools/ is no package)."""
    spec = importlib.util.spec_from_file_location("sizes", ROOT / "tools" / "sizes.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_size_report_sees_a_long_function_and_not_a_long_signature(tmp_path: Path) -> None:
    sizes = load_sizes()
    limit = sizes.MAX_FUNCTION_LINES
    room = tmp_path / "src" / "cli"
    room.mkdir(parents=True)
    options = "".join(f"    option_{i}: int = 0,\n" for i in range(60))
    body = "".join(f"x = {i}\n" for i in range(limit))
    (room / "command.py").write_text(
        f'def command(\n{options}) -> None:\n    """Help."""\n{textwrap.indent(body, " " * 4)}\n\n'
        f"class Kind:\n    def method(self) -> None:\n{textwrap.indent(body, ' ' * 8)}"
    )
    (room / "long.py").write_text("x = 0\n" * (sizes.MAX_MODULE_LINES + 1))
    assert sizes.function_lengths(room / "command.py", tmp_path) == {
        "src/cli/command.py:command": limit + 1,  # its docstring and body, not the 60 options
        "src/cli/command.py:Kind.method": limit,
    }
    long_ones = {"src/cli/command.py:command": limit + 1, "src/cli/long.py": sizes.MAX_MODULE_LINES + 1}
    assert sizes.oversized(tmp_path, ("src",)) == long_ones
