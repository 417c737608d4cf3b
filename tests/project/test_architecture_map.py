"""docs/architecture.md stays a map of the code as it is: short, linked from the README, its picture drawn
from the source committed beside it, and every file, package and thread it names a real one.

The map names files by their path under ``src/tankdaq`` (``acquire/pipeline.py``) or the repository's
(``docs/img/threads.py``); the picture names the threads by the names tankdaq gives them.
"""

from __future__ import annotations

import ast
import hashlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src" / "tankdaq"
MAP = ROOT / "docs" / "architecture.md"
PICTURE = ROOT / "docs" / "img" / "threads.svg"
PICTURE_SOURCE = ROOT / "docs" / "img" / "threads.py"

#: The map's length the issue set (about a screenful or three: read in one sitting).
MAX_LINES = 150
#: Threads tankdaq names that no decay crosses: the heartbeat of a long, silent step (an install, a build).
NOT_ON_A_DECAYS_PATH = {"tankdaq-heartbeat"}


def thread_names(root: Path = SRC) -> set[str]:
    """The ``name=`` of every ``threading.Thread(...)`` in the sources: a literal, or a module constant."""
    names: set[str] = set()
    for path in root.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        constants = {
            target.id: node.value.value
            for node in tree.body
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
            if isinstance(node.value.value, str)
            for target in node.targets
            if isinstance(target, ast.Name)
        }
        calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call)]
        for call in calls:
            if getattr(call.func, "attr", getattr(call.func, "id", "")) != "Thread":
                continue
            for keyword in (k for k in call.keywords if k.arg == "name"):
                if isinstance(keyword.value, ast.Constant) and isinstance(keyword.value.value, str):
                    names.add(keyword.value.value)
                elif isinstance(keyword.value, ast.Name) and keyword.value.id in constants:
                    names.add(constants[keyword.value.id])
    return names


def test_the_map_is_short_and_the_readme_links_it_and_the_performance_page() -> None:
    lines = MAP.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_LINES, f"docs/architecture.md: {len(lines)} lines, over the {MAX_LINES} of a map"
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "`docs/architecture.md`" in readme and "`docs/performance.md`" in readme


def test_the_picture_is_in_the_map_and_drawn_from_the_source_beside_it() -> None:
    assert "](img/threads.svg)" in MAP.read_text(encoding="utf-8")
    drawn_from = re.search(r"docs/img/threads\.py sha256 ([0-9a-f]{64})", PICTURE.read_text(encoding="utf-8"))
    assert drawn_from, "docs/img/threads.svg does not say which source drew it"
    source = hashlib.sha256(PICTURE_SOURCE.read_bytes()).hexdigest()
    assert drawn_from.group(1) == source, "docs/img/threads.py changed since it drew the SVG: run it again"


def named_paths(text: str) -> list[tuple[str, str]]:
    """(package row or "", name) of every ``x/y.py``, ``y.py`` and ``x/`` the map writes in backticks; a bare
    file name in a package's row of the table is that package's."""
    found = []
    for line in text.splitlines():
        row = re.match(r"\| `((?:[a-z_]+/)+)` \|", line)
        for name in re.findall(r"`((?:[a-z_]+/)*[a-z_0-9]+\.py|(?:[a-z_]+/)+)`", line):
            found.append((row.group(1) if row and "/" not in name else "", name))
    return found


def exists(package: str, name: str) -> bool:
    """In src/tankdaq (a bare name of a package row: anywhere in that package) or in the repository."""
    if package:
        return any((SRC / package).rglob(name))
    return (SRC / name).exists() or (ROOT / name).exists()


def test_every_file_and_package_the_map_names_exists() -> None:
    found = named_paths(MAP.read_text(encoding="utf-8"))
    assert len(found) > 60 and ("", "xsens/stream_decoder.py") in found, "the map's names were not found"
    generated = ("build/",)  # make docs writes the API reference there
    missing = sorted({f"{p}{n}" for p, n in found if not n.startswith(generated) and not exists(p, n)})
    assert not missing, f"docs/architecture.md names what is not in src/tankdaq nor the repository: {missing}"


@pytest.mark.slow
def test_the_picture_names_every_thread_a_decay_crosses_and_no_other() -> None:
    drawn = set(re.findall(r"tankdaq-[a-z]+(?:-[a-z]+)*", PICTURE_SOURCE.read_text(encoding="utf-8")))
    named = {name for name in thread_names() if name.startswith("tankdaq-")}
    assert {"tankdaq-read", "tankdaq-live-fit", "tankdaq-catalogue"} <= named, "no thread names were found"
    assert drawn <= named, f"the picture draws threads tankdaq no longer starts: {sorted(drawn - named)}"
    missing = named - NOT_ON_A_DECAYS_PATH - drawn
    assert not missing, f"threads tankdaq starts that docs/img/threads.py does not draw: {sorted(missing)}"


def test_the_thread_finder_sees_a_literal_and_a_constant_name(tmp_path: Path) -> None:
    (tmp_path / "probe.py").write_text(
        'import threading\nNAME = "tankdaq-probe"\n'
        'threading.Thread(target=print, name=NAME)\nThread(target=print, name="tankdaq-other")\n'
        'threading.Timer(1, print, kwargs={"name": "tankdaq-not-a-thread"})\n'
    )
    assert thread_names(tmp_path) == {"tankdaq-probe", "tankdaq-other"}
