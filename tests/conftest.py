"""Fixtures every test module may use.

- Every test's run catalogue is a temporary file: no test ever writes the user's own catalogue.
- ``simulator``: a simulated MTi-G serving on a real pty, stopped when the test ends.
- ``record_settings``: record settings for the built-in simulated MTi-G, writing into the test's folder.
- ``decay_recording``: one short decay recorded end to end into a real MCAP file, made once a session.
- ``private_tempdir``: the temporary folder for this test alone, where a simulator would put its pty link.
- ``postgres_url``: a throwaway PostgreSQL server for a test module's catalogues (skipped with the reason);
  ``catalogue_url``: a test's catalogue, once a SQLite file and once that server's database.

tankdaq is imported inside the fixtures, so collecting a test that uses none of them costs nothing.
The modules that hold a long test are run first (``pytest_collection_modifyitems``).
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

#: pytest caches a test module rewritten for its asserts only where bytecode may be written: with
#: PYTHONDONTWRITEBYTECODE set (as here and on CI), each worker rewrote and compiled every test module
#: again, half of its collection. The test processes write their bytecode; the processes they start keep
#: the environment's setting.
sys.dont_write_bytecode = False

if TYPE_CHECKING:
    from tankdaq.acquire.daemon import RecordSettings
    from tankdaq.device.simulator import SimulatedMTi


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The modules given a timeout beyond the default first (the docs' examples and the wheel: minutes
    each), then those holding a test marked ``slow``, each module's tests together and in their order:
    the workers then share the short tests at the end instead of one waiting on another's long one (a
    module's fixtures are still made once)."""
    longest: dict[str, float] = {}
    for item in items:
        module = item.nodeid.split("::")[0]
        marker = item.get_closest_marker("timeout")
        allowed = float(marker.args[0]) if marker is not None and marker.args else 0.0
        longest[module] = max(longest.get(module, 0.0), allowed)
    slow = {item.nodeid.split("::")[0] for item in items if item.get_closest_marker("slow") is not None}
    items.sort(
        key=lambda item: (-longest[item.nodeid.split("::")[0]], item.nodeid.split("::")[0] not in slow)
    )


#: The simulator fixture's device clock against the wall clock: a decay in a few seconds.
SIMULATOR_SPEED = 10.0


@pytest.fixture(autouse=True, scope="session")
def _catalogue_in_a_temp_folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """``TANKDAQ_CATALOGUE`` for the session (and every process a test starts inherits it)."""
    patch = pytest.MonkeyPatch()
    patch.setenv("TANKDAQ_CATALOGUE", str(tmp_path_factory.mktemp("catalogue") / "catalogue.sqlite"))
    yield
    patch.undo()


@pytest.fixture
def simulator() -> Iterator[SimulatedMTi]:
    """A simulated MTi-G on a real pty, opened by path like hardware (``simulator.link``, ``.port``).

    It plays the swath's roll decay at 100 Hz, its clock ``SIMULATOR_SPEED`` times the wall clock. When
    the test ends, passed or failed, it is stopped and its pty, links and folder removed.
    """
    from tankdaq.config.hulls import hull_scenario
    from tankdaq.device.simulator import SimulatedMTi

    with SimulatedMTi(hull_scenario(rate_hz=100), speed=SIMULATOR_SPEED) as device:
        yield device


@pytest.fixture
def private_tempdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``tempfile``'s folder for this test alone: a simulator started in this process makes its folder
    (pty link, by-id links) there, so a test can tell that nothing was started or that nothing is left."""
    private = tmp_path / "tmp"
    private.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(private))
    return private


@pytest.fixture
def record_settings(tmp_path: Path) -> Callable[..., RecordSettings]:
    """Makes ``RecordSettings`` for the built-in simulated MTi-G (``tests/support/record_settings.py``: swath
    roll at T from 8 deg, no viewer) writing into the test's ``tmp_path``; a test names only what it changes,
    ``record_settings(runs=1, port=simulator.link)``, and another folder as ``out_dir=``."""

    from support.record_settings import sim_record_settings

    def make(**overrides: object) -> RecordSettings:
        return sim_record_settings(tmp_path, **overrides)

    return make


@pytest.fixture(scope="session")
def decay_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One roll decay of the swath recorded end to end: the simulated MTi-G on its pty, the driver, the
    release detection, the live fit and the MCAP writer (raw bytes, samples, events, fits), device clock at
    8x, seed 5. One file for the whole session: read it, or copy it before changing anything."""
    from support.record_settings import sim_record_settings
    from tankdaq.acquire.daemon import RecordDaemon

    settings = sim_record_settings(tmp_path_factory.mktemp("decay"), runs=1, sim_speed=8.0, sim_seed=5)
    (outcome,) = RecordDaemon(settings).run()
    assert outcome.path is not None, "the simulated decay was not recorded"
    return outcome.path


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    """A throwaway PostgreSQL server (tests/support/pg_server.py), stopped at the module's end; skipped with
    the reason where the server binaries are not installed."""
    from support.pg_server import throwaway_postgres, why_not

    reason = why_not()
    if reason is not None:
        pytest.skip(reason)
    with throwaway_postgres() as url:
        yield url


@pytest.fixture(params=["sqlite", "postgresql"])
def catalogue_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty catalogue: a SQLite file, or a throwaway PostgreSQL server's database (skipped where
    there is none; one server per module, so one test of a module may use it)."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    return str(request.getfixturevalue("postgres_url"))


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real recording of one swath roll decay from 8 deg, 20 s at the simulated sensor's rate (about
    150 kB of MCAP); a module that needs another defines its own."""
    from tankdaq.campaign.synthetic import SimulatedTest, write_simulated_campaign

    folder = tmp_path_factory.mktemp("rec")
    (path,) = write_simulated_campaign(
        folder, ["swath"], "roll", [1.0], [8.0], "mcap", test=SimulatedTest(duration_s=20.0)
    )
    return path
