"""The IMO table (MSC.1/Circ.1200): Bertin's N against mean amplitude from decays at several initial angles,
checked against the truth's coefficients; what the decays do not reach and the initial angle that would;
and the real KVLCC2 decay (issue 38 item 4)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tankdaq.campaign.groups import GroupKey
from tankdaq.ident.derived import bertin_n_per_deg
from tankdaq.ident.free_decay import cut_free_decays
from tankdaq.ident.imo_table import (
    IMO_AMPLITUDES_DEG,
    DecayCover,
    decay_cover,
    imo_markdown,
    imo_table,
    imo_tables,
    initial_angle_deg,
)
from tankdaq.ident.inputs import read_decays
from tankdaq.ident.interval_labels import ANGLES_STD, FIT_STD
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

TRUTH = {"b1": 0.05, "b2": 0.3, "c1": 4.0}
ANGLES_DEG = (12.0, 18.0, 24.0)
KVLCC2 = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)


def decay(angle_deg: float, duration_s: float, seed: int) -> DecayRun:
    """A decay of ``TRUTH`` from rest at ``angle_deg`` with an MTi-G's noise, on an offset equilibrium."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 0.02)
    angle, rate = simulate_decay(TRUTH, t, math.radians(angle_deg))
    noisy = angle + 0.004 + rng.normal(0.0, 3e-4, t.size)
    return DecayRun(t, noisy, rate + rng.normal(0.0, 2e-3, t.size), name=f"{angle_deg:g}deg")


def cover_of(angle_deg: float, duration_s: float = 30.0, seed: int = 1) -> DecayCover:
    run = decay(angle_deg, duration_s, seed)
    fit = OutputErrorFit(["b1", "b2", "c1"]).fit([run])
    return decay_cover(GroupKey("tanker", "roll", 1.0, round(angle_deg)), [run], fit)


@pytest.fixture(scope="module")
def covers() -> list[DecayCover]:
    return [cover_of(angle, seed=k) for k, angle in enumerate(ANGLES_DEG)]


def test_n_at_each_imo_amplitude_is_the_truths_from_the_decays_that_cover_it(
    covers: list[DecayCover],
) -> None:
    table = imo_table(covers)
    assert [row.amplitude_deg for row in table.rows] == list(IMO_AMPLITUDES_DEG)
    # the measured initial angles, about the fitted equilibrium (the decays sit 0.23 deg off zero)
    np.testing.assert_allclose(table.initial_angles_deg, ANGLES_DEG, atol=0.02)
    by_amplitude = {row.amplitude_deg: row for row in table.rows}
    for amplitude in (10.0, 15.0, 20.0):
        row = by_amplitude[amplitude]
        truth = bertin_n_per_deg(TRUTH, math.radians(amplitude))
        assert row.bertin_n_per_deg == pytest.approx(truth, rel=2e-3)
        assert 0.0 < row.uncertainty_per_deg < 0.01 * truth
    # N depends on the amplitude (quadratic damping): the table is not one number
    assert by_amplitude[10.0].bertin_n_per_deg > 1.15 * by_amplitude[20.0].bertin_n_per_deg
    # who covers what: 10 deg by all three decays, 15 by two, 20 by the 24 deg one alone
    assert [len(by_amplitude[a].initial_angles_deg) for a in (10.0, 15.0, 20.0)] == [3, 2, 1]
    assert by_amplitude[10.0].interval == ANGLES_STD and by_amplitude[15.0].interval == ANGLES_STD
    assert by_amplitude[20.0].interval == FIT_STD
    values = [c.bertin_n(15.0)[0] for c in covers if c.covers(15.0)]
    assert by_amplitude[15.0].uncertainty_per_deg == pytest.approx(np.std(values, ddof=1) / math.sqrt(2))
    assert by_amplitude[20.0].uncertainty_per_deg == pytest.approx(covers[-1].bertin_n(20.0)[1])


def test_an_amplitude_above_the_decays_names_the_initial_angle_that_reaches_it(
    covers: list[DecayCover],
) -> None:
    table = imo_table(covers)
    (missing,) = table.missing
    assert missing.amplitude_deg == 25.0 and math.isnan(missing.bertin_n_per_deg) and missing.interval is None
    needed = missing.needed_initial_deg
    assert needed is not None and 25.0 < needed < 30.0
    assert "25° (needs an initial angle of about" in table.missing_line()
    # the decay from that angle first passes a mean amplitude of 25 deg; one from 1 deg less does not
    reached = cover_of(needed, duration_s=3.0)
    short = cover_of(needed - 1.0, duration_s=3.0)
    assert max(reached.mean_amplitude_deg) == pytest.approx(25.0, abs=0.1)
    assert max(short.mean_amplitude_deg) < 24.5


def test_decays_that_end_above_an_amplitude_say_to_record_longer() -> None:
    cut = [cover_of(angle, duration_s=6.0, seed=3) for angle in (18.0, 24.0)]
    table = imo_table(cut)
    low, _ = table.covered_deg
    assert low > 10.0
    by_amplitude = {row.amplitude_deg: row for row in table.rows}
    assert not by_amplitude[10.0].reached and by_amplitude[10.0].needed_initial_deg is None
    assert "10° (the decays end at" in table.missing_line() and "record them longer" in table.missing_line()
    assert by_amplitude[15.0].reached


def test_one_table_per_condition_and_its_markdown(covers: list[DecayCover]) -> None:
    other = [DecayCover(**{**c.__dict__, "draft": 1.1}) for c in covers[:2]]
    tables = imo_tables([*covers, *other])
    assert [(t.hull, t.draft) for t in tables] == [("tanker", 1.0), ("tanker", 1.1)]
    text = imo_markdown(tables)
    assert text.count("Bertin's N (MSC.1/Circ.1200)") == 2 and "± (1σ, initial angles)" in text
    assert imo_markdown([]) == ""
    points = tables[0].as_dict()["points"]  # mean angle against decrement per half cycle, as measured
    assert len(points) == sum(len(c.mean_amplitude_deg) for c in covers)
    assert points[0] == {
        "initial_angle_deg": covers[0].initial_deg,
        "mean_amplitude_deg": covers[0].mean_amplitude_deg[0],
        "decrement_deg": covers[0].decrement_deg[0],
    }
    record = tables[0].records()[0]
    assert record["draft"] == "T" and record["interval"] == ANGLES_STD.text


def test_initial_angle_is_measured_not_nominal() -> None:
    run = decay(11.3, 4.0, seed=4)
    assert initial_angle_deg([run], [0.004]) == pytest.approx(11.3, abs=0.01)
    assert initial_angle_deg([run], [0.0]) == pytest.approx(11.3 + math.degrees(0.004), abs=0.01)


@pytest.mark.skipif(not KVLCC2.is_file(), reason=f"the KVLCC2 roll decay is not at {KVLCC2}")
def test_kvlcc2_decay_gives_n_up_to_its_initial_angle_and_says_what_it_misses() -> None:
    runs = cut_free_decays(read_decays(KVLCC2, None, "time", "phi", None, "rad"), None, None)
    fit = OutputErrorFit(["b1", "b2", "c1", "c3"]).fit(runs)
    cover = decay_cover(GroupKey("kvlcc2", "roll", 1.0, 10.0), runs, fit)
    table = imo_table([cover])
    low, high = table.covered_deg
    assert 0.5 <= low < 2.0 and table.initial_angles_deg[0] - 1.0 < high < table.initial_angles_deg[0]
    reached = [row for row in table.rows if row.reached]
    assert [row.amplitude_deg for row in reached] == [a for a in IMO_AMPLITUDES_DEG if a <= high]
    for row in reached:  # the model's N runs through the measured decrements per half cycle there
        near = [
            d / m**2
            for m, d in zip(cover.mean_amplitude_deg, cover.decrement_deg, strict=True)
            if abs(m - row.amplitude_deg) < 1.0
        ]
        assert row.interval == FIT_STD and row.bertin_n_per_deg == pytest.approx(np.median(near), rel=0.25)
    for row in table.missing:  # above its initial angle: a larger one, estimated
        assert row.needed_initial_deg is not None and row.needed_initial_deg > row.amplitude_deg


def test_an_amplitude_beyond_any_release_is_said_to_be_out_of_reach() -> None:
    heavy = {"b1": 0.05, "b2": 15.0, "c1": 4.0}  # N about 0.35/deg: 15 deg needs a release from 54 deg
    cover = DecayCover("swath", "roll", 1.0, 8.0, 8.0, (2.0, 6.0), (0.4, 3.5), heavy, np.zeros((3, 3)))
    table = imo_table([cover])
    needed = {row.amplitude_deg: row.needed_initial_deg for row in table.missing}
    for amplitude in (10.0, 15.0, 20.0, 25.0):  # by hand: phi0 = phi_m + N(phi_m) phi_m^2 / 2
        n = bertin_n_per_deg(heavy, math.radians(amplitude))
        assert needed[amplitude] == pytest.approx(amplitude + 0.5 * n * amplitude**2, rel=1e-12)
    assert needed[10.0] < 45.0 < needed[15.0]
    line = table.missing_line()
    assert f"10° (needs an initial angle of about {needed[10.0]:.1f}°)" in line
    assert "15° (needs an initial angle of about" in line and "beyond any release (45°)" in line
