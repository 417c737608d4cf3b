"""The release instant from a swaying hold, with its 95 % interval (issue 38; the full 200 x 3 count is in
bench/bench_release_sway.py), and the interval read back: an older file without it says unknown."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

import tankdaq
from tankdaq.acquire import release_instant
from tankdaq.acquire.release import ReleaseDetector
from tankdaq.catalogue.rows import recording_row
from tankdaq.config.hulls import hull_scenario
from tankdaq.physics.scenario import SWAY_LINES, Handling
from tankdaq.physics.truth import TICKS_PER_S
from tankdaq.samples import SAMPLE_DTYPE
from tankdaq.store.writer import RecordingWriter

RELEASES = 10  # per rate


def _errors(rate_hz: int) -> tuple[list[float], list[float], list[float]]:
    """Errors (s) and 95 % half-widths (s) of the releases from a swaying hold, and the true rates (rad/s)."""
    samples, trace = hull_scenario(runs=RELEASES, seed=70 + rate_hz, rate_hz=rate_hz, decay_s=18,
                                   handling=Handling.swaying()).samples()  # fmt: skip
    found = [e for e in ReleaseDetector(axis=trace.axis).fit(samples).events_ if e.kind == "released"]
    errors, u95s, rates = [], [], []
    for run in trace.runs:
        near = [e for e in found if abs(e.index - run.release_index) < 50]
        assert near and run.release_ticks is not None and run.rate0_rad_s is not None
        errors.append(near[0].release_t - run.release_ticks / TICKS_PER_S)
        u95s.append(near[0].release_u95_s)
        rates.append(run.rate0_rad_s)
    return errors, u95s, rates


def test_the_swaying_hold_leaves_the_model_with_a_rate() -> None:
    """The scenario's swaying hold: the lines asked for, at random phases (the still hold's stream kept)."""
    assert Handling.swaying().sway_lines == SWAY_LINES == ((0.15, 0.9), (0.05, 2.3))
    still = hull_scenario(runs=2, seed=5).trace()
    again = hull_scenario(runs=2, seed=5, handling=Handling()).trace()
    np.testing.assert_array_equal(still.angle, again.angle)
    trace = hull_scenario(runs=12, seed=6, decay_s=12, handling=Handling.swaying()).trace()
    rates = np.degrees([abs(r.rate0_rad_s or 0.0) for r in trace.runs])
    # the hand's rate from the sway alone reaches 0.15*2pi*0.9 + 0.05*2pi*2.3 = 1.57 deg/s; phases spread it
    assert rates.max() > 0.8 and np.median(rates) > 0.2, rates


@pytest.mark.slow
def test_the_release_from_a_swaying_hold_is_within_10_ms_and_its_interval_covers() -> None:
    """30 releases at 100, 200 and 400 Hz. Tolerance: the bench finds 100 % within 10 ms and a coverage of
    94-95.5 % over 200 per rate; here at least 28 of 30 within 10 ms (a true 95 % share gives that with
    probability 0.81, the bench's share with ~1) and at least 26 of 30 covered (a true 95 % gives that with
    0.98, 94 % with 0.96). The still hold's cubic alone (no spline) misses 10 ms (next test)."""
    errors, u95s = [], []
    for rate_hz in (100, 200, 400):
        e, u, rates = _errors(rate_hz)
        errors += e
        u95s += u
        assert max(abs(r) for r in rates) > math.radians(0.5)  # the hand was moving when it let go
    err = np.abs(np.array(errors))
    assert np.sum(err <= 0.010) >= 28, np.round(1e3 * err, 2)
    assert all(0 < u < 0.02 for u in u95s), u95s
    assert np.sum(err <= np.array(u95s)) >= 26, np.round(1e3 * (err - np.array(u95s)), 2)


@pytest.mark.slow
def test_a_cubic_hold_alone_is_moved_by_the_sway(monkeypatch: pytest.MonkeyPatch) -> None:
    """What the spline is for: without it (the old estimator), a release 10 ms off."""
    monkeypatch.setattr(release_instant, "SWAY_KNOTS_S", ())
    errors, _, _ = _errors(200)
    assert max(abs(e) for e in errors) > 0.010, errors


def test_the_interval_is_in_the_file_the_api_and_the_catalogue(decay_recording: Path) -> None:
    """A decay recorded end to end: the release event's data carries the instant's 95 % half-width (read
    with the official mcap reader); ``tankdaq.read`` and the catalogue's row give the same."""
    with open(decay_recording, "rb") as stream:
        events = [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(topics=["/events"])]
    (release,) = [event for event in events if event["kind"] == "release"]
    u95 = release["data"]["release_u95_s"]
    assert release["data"]["release_se_s"] < u95 < 0.02
    assert tankdaq.read(decay_recording).decays[0].release_u95_s == u95
    row, _ = recording_row(decay_recording)
    assert (row["release_t_s"], row["release_u95_s"]) == (release["t_s"], u95)


def test_a_file_without_the_interval_reads_as_unknown(tmp_path: Path) -> None:
    """A recording written before the interval: the API and the catalogue say unknown (None), never 0."""
    t = np.arange(0.0, 12.0, 0.01)
    samples = np.zeros(t.size, dtype=SAMPLE_DTYPE)
    samples["t"], samples["ticks"], samples["az"] = t, np.round(t * 1e4).astype(np.int64), 9.81
    free = t >= 2.0
    samples["roll"] = np.radians(5.0) * np.where(
        free, np.exp(-0.1 * (t - 2.0)) * np.cos(3.0 * (t - 2.0)), 1.0
    )
    path = tmp_path / "old.mcap"
    with RecordingWriter(path, {"axis": "roll"}, {}) as writer:
        writer.write_samples(samples)
        writer.write_event(
            "release", "released at 5.000 deg", 2.0, {"angle_initial_deg": 5.0, "release_se_s": 0.001}
        )
    recording = tankdaq.read(path)
    assert recording.decays[0].release_u95_s is None and recording.meta["release_u95_s"] == [None]
    row, _ = recording_row(path)
    assert row["release_t_s"] == 2.0 and row["release_u95_s"] is None


def test_a_catalogue_of_version_4_gains_the_release_columns_empty(tmp_path: Path) -> None:
    """The migration: a version 4 catalogue's rows keep their values and say the release unknown (NULL)."""
    import sqlalchemy as sa

    from tankdaq.catalogue.database import open_catalogue
    from tankdaq.catalogue.schema import SCHEMA_VERSION, decays, schema_version

    url = f"sqlite:///{tmp_path / 'old.sqlite'}"
    open_catalogue(url).close()
    engine = sa.create_engine(url)
    with engine.begin() as connection:  # back to version 4: without the columns, with a row
        for column in ("release_t_s", "release_u95_s"):
            connection.exec_driver_sql(f"ALTER TABLE decays DROP COLUMN {column}")
        connection.execute(schema_version.delete().where(schema_version.c.version > 4))
        connection.exec_driver_sql(
            "INSERT INTO decays (sha256, path, size_bytes, complete, created_utc, updated_utc) "
            "VALUES ('ab', '/old.mcap', 1, 1, 'then', 'then')"
        )
    engine.dispose()
    with open_catalogue(url) as catalogue, catalogue.engine.connect() as connection:
        row = connection.execute(sa.select(decays)).one()
        version = connection.execute(sa.select(sa.func.max(schema_version.c.version))).scalar()
    assert SCHEMA_VERSION == version >= 5
    assert (row.path, row.release_t_s, row.release_u95_s) == ("/old.mcap", None, None)
