"""Where the free decay ends: generated decays with a carriage stop or a second push, and KVLCC2."""

from __future__ import annotations

import math

import numpy as np
import pytest

from support.ident_helpers import KVLCC2_21338
from tankdaq.errors import InputError
from tankdaq.ident.free_decay import cut_free_decay, find_free_end
from tankdaq.ident.inputs import read_decays
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

TRUTH = {"b1": 0.3, "b2": 0.4, "c1": 14.0, "c3": 20.0}
PERIOD_S = 2 * math.pi / math.sqrt(TRUTH["c1"])
RATE_HZ = 100.0


def forced_decay(forcing, duration_s: float = 30.0, angle0_deg: float = 8.0, seed: int = 0):
    """(t, angle, rate) of the decay equation from rest at ``angle0_deg`` plus ``forcing(t)`` (rad/s²),
    with white noise like an MTi-G's."""
    t = np.arange(0.0, duration_s, 1 / RATE_HZ)
    angle, rate = simulate_decay(TRUTH, t, math.radians(angle0_deg), rtol=1e-9, atol=1e-11, forcing=forcing)
    rng = np.random.default_rng(seed)
    return t, angle + rng.normal(0, 3e-4, t.size), rate + rng.normal(0, 2e-3, t.size)


def half_sine(start_s: float, length_s: float, peak: float):
    return lambda tt: (
        peak * math.sin(math.pi * (tt - start_s) / length_s) if start_s <= tt <= start_s + length_s else 0.0
    )


STOP_S = 12.0  # the carriage starts to decelerate


def carriage_stop_run(with_speed: bool) -> DecayRun:
    """A decay at speed; from STOP_S the carriage decelerates over 2 s, heeling the model a little."""
    t, angle, rate = forced_decay(half_sine(STOP_S, 2.0, 0.15))
    channels = {}
    if with_speed:
        speed = np.clip(1.2 * (1 - (t - STOP_S) / 2.0), 0.0, 1.2)
        channels["carriage_speed_m_s"] = speed + np.random.default_rng(1).normal(0, 0.005, t.size)
    return DecayRun(t, angle, rate, name="stop", channels=channels)


def assert_matches_within_intervals(cut_fit: OutputErrorFit, clean_fit: OutputErrorFit) -> None:
    """Every coefficient of the clean record's fit lies in the cut record's 95 % interval."""
    for term, value in clean_fit.coefficients_.items():
        low, high = cut_fit.ci95_[term]
        assert low <= value <= high, (term, value, (low, high))


@pytest.fixture(scope="module")
def clean_fit() -> OutputErrorFit:
    t, angle, rate = forced_decay(lambda _t: 0.0)
    return OutputErrorFit(tuple(TRUTH)).fit([DecayRun(t, angle, rate, name="clean")])


@pytest.mark.parametrize("with_speed", [True, False], ids=["speed channel", "roll only"])
def test_a_carriage_stop_ends_the_free_decay_within_a_period(with_speed, clean_fit):
    run = carriage_stop_run(with_speed)
    end = find_free_end(run)
    assert abs(end.t_s - STOP_S) <= PERIOD_S, end
    assert end.kind == ("channel" if with_speed else "excitation")
    cut = cut_free_decay(run)
    assert cut.meta["cut"]["reason"] == end.reason and "s after release" in cut.meta["cut"]["line"]
    fit = OutputErrorFit(tuple(TRUTH)).fit([cut])
    assert_matches_within_intervals(fit, clean_fit)
    whole = OutputErrorFit(tuple(TRUTH)).fit([run])
    assert whole.r2_angle_ < fit.r2_angle_  # what the issue saw: the whole record fits worse


PUSH_S = 9.1


def test_a_second_push_is_an_excitation_and_a_csv_splits_there(tmp_path, clean_fit):
    t, angle, rate = forced_decay(half_sine(PUSH_S, 0.4, 1.5), duration_s=40.0)
    run = DecayRun(t, angle, rate, name="push")
    end = find_free_end(run)
    assert end.kind == "excitation" and abs(end.t_s - PUSH_S) <= PERIOD_S, end
    assert_matches_within_intervals(OutputErrorFit(tuple(TRUTH)).fit([cut_free_decay(run)]), clean_fit)
    path = tmp_path / "two.csv"
    np.savetxt(path, np.column_stack([t, np.degrees(angle), np.degrees(rate)]), delimiter=",",
               header="time_s,angle_deg,rate_deg_s", comments="")  # fmt: skip
    first, second = read_decays(path)
    assert (first.name, second.name) == ("two#1", "two#2")
    assert first.t[-1] <= PUSH_S + PERIOD_S and second.t[0] > PUSH_S
    assert "excitation" in cut_free_decay(first).meta["cut"]["reason"]


def test_start_and_end_override(tmp_path):
    run = carriage_stop_run(with_speed=False)
    cut = cut_free_decay(run, start_s=1.0, end_s=5.0)
    assert cut.t[0] - run.t[0] == pytest.approx(1.0, abs=0.011)
    assert cut.t[-1] - run.t[0] == pytest.approx(5.0, abs=0.011)
    assert "--end 5 s" in cut.meta["cut"]["line"]
    with pytest.raises(InputError, match="fewer than 20 samples"):
        cut_free_decay(run, start_s=5.0, end_s=5.05)


@pytest.mark.skipif(not KVLCC2_21338.is_file(), reason=f"KVLCC2 reference run not found at {KVLCC2_21338}")
def test_kvlcc2_at_zero_speed_is_not_cut_short():
    """A 0 kn decay ending at about 1.1 deg (reference §7): nothing stops it; the slow yaw drift of psi
    is not a carriage stop."""
    (run,) = read_decays(KVLCC2_21338, time_col="time", angle_col="phi", rate_col=None, angle_unit="rad")
    end = find_free_end(run)
    assert end.kind == "record" and end.index == run.t.size, end
    assert "psi" in run.channels


@pytest.mark.skipif(not KVLCC2_21338.is_file(), reason=f"KVLCC2 reference run not found at {KVLCC2_21338}")
def test_a_gap_in_the_record_is_named_and_dropped_samples_are_not():
    """Run 21338 with 5 s of samples missing: the swings around the gap looked out of step, and the cut
    said "a disturbance: a half-period of 6.36 s". It is the gap, named, and the free part ends where it
    starts. Every tenth sample missing at random (dropped packets) ends nothing."""
    (run,) = read_decays(KVLCC2_21338, time_col="time", angle_col="phi", rate_col=None, angle_unit="rad")
    gap_at = run.t[0] + 40.0
    keep = (run.t < gap_at) | (run.t > gap_at + 5.0)
    gapped = DecayRun(run.t[keep], run.angle[keep], None, name="gapped")
    end = find_free_end(gapped)
    assert end.kind == "record" and "no samples for 5.0" in end.reason and "a gap in the record" in end.reason
    assert gapped.t[end.index - 1] < gap_at <= gapped.t[end.index]
    sparse = np.random.default_rng(1).random(run.t.size) > 0.1
    dropped = DecayRun(run.t[sparse], run.angle[sparse], None, name="dropped")
    assert find_free_end(dropped).index == dropped.t.size
