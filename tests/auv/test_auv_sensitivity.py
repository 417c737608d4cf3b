"""Sensitivity analysis: manoeuvre outputs on known signals, and the perturbation indices."""

from __future__ import annotations

import numpy as np
import pytest

from tankdaq.auv.model import StateRecord, simulate_zigzag
from tankdaq.auv.sensitivity import OUTPUTS, manoeuvre_outputs, sensitivity_analysis
from tankdaq.auv.vehicle import load_vehicle
from tankdaq.errors import InputError


def test_outputs_of_a_known_synthetic_zigzag():
    t = np.arange(0.0, 60.0, 0.01)
    period, amplitude, switch = 20.0, np.radians(12.0), np.radians(10.0)
    theta = -amplitude * np.sin(2 * np.pi * t / period)
    z = 0.7 * (1 - np.cos(2 * np.pi * t / period))  # depth swings 1.4 m between extremes
    reversals = np.arange(3.0, 60.0, period / 2)
    states = {
        "theta": theta,
        "z": z,
        "u": np.full_like(t, 1.4),
        "q": np.gradient(theta, t),
        "w": np.zeros_like(t),
        "x": 1.4 * t,
        "delta_s": np.zeros_like(t),
    }
    record = StateRecord(t, states, switch_times=reversals)
    out = manoeuvre_outputs(record, switch)
    assert out["overshoot"] == pytest.approx(amplitude - switch, rel=1e-4)
    assert out["depth_change"] == pytest.approx(1.4, rel=1e-4)
    assert out["period"] == pytest.approx(period, rel=1e-12)
    assert out["speed"] == pytest.approx(1.4)


def test_central_difference_matches_a_direct_perturbation():
    nps = load_vehicle("nps_auv2")
    delta, theta = np.radians(15.0), np.radians(10.0)
    result = sensitivity_analysis(nps, delta, theta, step=0.05, terms=["M_uq", "Z_w|w|"])

    def overshoot(scale: float) -> float:
        model = nps.with_derivatives({"M_uq": nps.coefficient("M_uq") * scale})
        return manoeuvre_outputs(simulate_zigzag(model, delta, theta), theta)["overshoot"]

    direct = (overshoot(1.01) - overshoot(0.99)) / (0.02 * overshoot(1.0))
    assert result.sensitivities["M_uq"]["overshoot"] == pytest.approx(direct, rel=0.05)
    assert result.ranking == ["M_uq", "Z_w|w|"]  # the Munk-like pitch damping term beats cross-flow drag


@pytest.mark.slow
def test_ranking_is_by_index_and_dominance_by_threshold():
    result = sensitivity_analysis(load_vehicle("nps_auv2"), dominant_threshold=0.2)
    indices = [result.index[n] for n in result.ranking]
    assert indices == sorted(indices, reverse=True)
    assert result.dominant == [n for n in result.ranking if result.index[n] >= 0.2]
    assert set(result.sensitivities[result.ranking[0]]) == set(OUTPUTS)
    assert result.to_dict()["ranking"] == result.ranking


def test_absent_derivatives_and_bad_steps_are_refused():
    nps = load_vehicle("nps_auv2")
    with pytest.raises(InputError, match="no \\['M_w\\|w\\|'\\]"):
        sensitivity_analysis(nps, terms=["M_w|w|"])
    with pytest.raises(InputError, match="fraction"):
        sensitivity_analysis(nps, step=10.0)
