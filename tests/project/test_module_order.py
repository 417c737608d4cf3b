"""The order the test modules are handed out in: the longest first, from tests/durations.json, which
tools/module_durations.py writes from a run's durations."""

from __future__ import annotations

import importlib.util
import json
import types
from pathlib import Path

import pytest

from conftest import DURATIONS, UNMEASURED_SLOW_S, expected_seconds

ROOT = Path(__file__).resolve().parents[2]

LOG = """\
============================= slowest durations ==============================
12.50s call     tests/viz/test_a.py::test_one[phone]
2.50s setup    tests/viz/test_a.py::test_one[phone]
0.40s call     tests/viz/test_a.py::test_two
3.00s call     tests/acquire/test_b.py::Test::test_three
0.30s call     tests/acquire/test_c.py::test_short
(2 durations < 0.005s hidden.  Use -vv to show these durations.)
"""


def load_tool(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    """tools/module_durations.py, loaded from its path (tools/ is no package; it reads mark_slow's lines)."""
    monkeypatch.syspath_prepend(str(ROOT / "tools"))
    spec = importlib.util.spec_from_file_location("module_durations", ROOT / "tools" / "module_durations.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_modules_time_is_its_phases_added_up_and_the_short_ones_are_left_out(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    tool = load_tool(monkeypatch)
    (tmp_path / "run.log").write_text(LOG)
    (tmp_path / "slower.log").write_text("20.00s call     tests/acquire/test_b.py::Test::test_three\n")
    out = tmp_path / "durations.json"
    assert tool.main([str(tmp_path / "run.log"), str(tmp_path / "slower.log")], out=out) == 0
    written = json.loads(out.read_text())
    assert written == {"tests/acquire/test_b.py": 20.0, "tests/viz/test_a.py": 15.4}  # the longest run's
    assert list(written) == ["tests/acquire/test_b.py", "tests/viz/test_a.py"]  # longest first
    assert tool.main([str(tmp_path / "missing.log")], out=out) == 2
    (tmp_path / "empty.log").write_text("no durations here\n")
    assert tool.main([str(tmp_path / "empty.log")], out=out) == 1
    assert json.loads(out.read_text()) == written  # a failed run leaves the file as it was


def test_the_longest_module_goes_first_and_an_unmeasured_slow_one_before_the_short_ones() -> None:
    known = {"tests/a.py": 50.0, "tests/b.py": 2.0}
    modules = ["tests/b.py", "tests/new_fast.py", "tests/a.py", "tests/new_slow.py"]
    ordered = sorted(modules, key=lambda m: expected_seconds(m, known, {"tests/new_slow.py"}), reverse=True)
    assert ordered == ["tests/a.py", "tests/new_slow.py", "tests/b.py", "tests/new_fast.py"]
    assert known["tests/a.py"] > UNMEASURED_SLOW_S > known["tests/b.py"]


def test_every_module_timed_is_still_here() -> None:
    """A module moved or renamed since the times were taken loses its place: write them again."""
    timed = json.loads(DURATIONS.read_text())
    gone = [module for module in timed if not (ROOT / module).is_file()]
    assert not gone, f"{gone}: run the suite with --durations=0 and python tools/module_durations.py LOG"
    assert max(timed.values()) > 60.0  # a whole run's times, the docs' examples among them
