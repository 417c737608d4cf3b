"""Derived results against closed forms and against simulated decays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tankdaq.ident.derived import (
    amplitude_table,
    b_eq,
    b_eq_band,
    bertin_n_per_deg,
    damping_ratio,
    dimensional,
    equivalent_frequency,
    extinction_curve,
    natural_period,
)
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun


def test_linear_model_closed_forms():
    c = {"b1": 0.4, "c1": 16.0}
    assert natural_period(c) == pytest.approx(2 * math.pi / 4.0)
    assert damping_ratio(c) == pytest.approx(0.4 / 8.0)
    assert b_eq(c, 0.2) == pytest.approx(0.4)


def test_b_eq_follows_ittc_eq_15_and_cubic_restoring_stiffens():
    c = {"b1": 0.1, "b2": 0.5, "b3": 0.2, "c1": 16.0, "c3": 40.0}
    a = math.radians(10)
    omega = math.sqrt(16.0 + 0.75 * 40.0 * a**2)
    assert equivalent_frequency(c, a) == pytest.approx(omega, rel=1e-9)
    expected = 0.1 + 8 / (3 * math.pi) * omega * a * 0.5 + 0.75 * (omega * a) ** 2 * 0.2
    assert b_eq(c, a) == pytest.approx(expected, rel=1e-9)
    # Bertin: mu_eq = N phi_a omega / pi with N per rad, reported per degree
    n_per_rad = math.pi * 0.5 * expected / (a * omega)
    assert bertin_n_per_deg(c, a) == pytest.approx(n_per_rad * math.pi / 180, rel=1e-9)


def test_measured_extinction_matches_the_models_curve():
    c = {"b1": 0.2, "b2": 0.6, "c1": 14.0}
    t = np.arange(3000) / 100.0
    angle, _ = simulate_decay(c, t, 0.3)
    curve = extinction_curve([DecayRun(t=t, angle=angle)], [0.0], c)
    model = np.interp(curve.mean_amplitude, curve.model_amplitude, curve.model_decrement)
    assert curve.mean_amplitude.size > 10
    # the energy-balance curve is first order in the damping: a few per cent here
    assert np.allclose(curve.decrement, model, rtol=0.05, atol=2e-4)


def test_delta_method_matches_monte_carlo_spread():
    c = {"b1": 0.2, "b2": 0.6, "c1": 14.0}
    cov = np.diag([1e-4, 4e-3, 1e-2])
    cov[0, 1] = cov[1, 0] = -0.8 * math.sqrt(1e-4 * 4e-3)
    point = amplitude_table(c, cov, [8.0])[0]
    rng = np.random.default_rng(0)
    draws = rng.multivariate_normal([0.2, 0.6, 14.0], cov, size=4000)
    values = [b_eq(dict(zip(c, d, strict=True)), math.radians(8.0)) for d in draws]
    assert point.b_eq_std == pytest.approx(np.std(values), rel=0.05)


def test_b_eq_band_is_the_amplitude_tables_b_eq_at_every_amplitude():
    """The report's band (one array pass) gives the table's B_eq and its delta-method spread."""
    c = {"b1": 0.2, "b2": 0.6, "b3": 1.5, "c1": 14.0, "c3": -30.0, "s1": 0.5}
    cov = np.diag([1e-4, 4e-3, 1e-2, 1e-2, 4.0, 1e-3])
    cov[0, 1] = cov[1, 0] = -0.8 * math.sqrt(1e-4 * 4e-3)
    amplitudes_deg = np.linspace(0.0, 25.0, 26)
    values, std = b_eq_band(c, cov, amplitudes_deg)
    table = amplitude_table(c, cov, amplitudes_deg)
    np.testing.assert_allclose(values, [p.b_eq for p in table], rtol=1e-12)
    np.testing.assert_allclose(std, [p.b_eq_std for p in table], rtol=1e-9)
    assert std[10] > 0 and values[25] > values[1]


def test_dimensional_inertia_from_displacement_and_gm():
    result = dimensional({"b1": 0.3, "c1": 14.0}, displacement_kg=30.0, gm_m=0.08, dry_inertia_kg_m2=1.2)
    inertia = 30.0 * 9.81 * 0.08 / 14.0
    assert result.total_inertia_kg_m2 == pytest.approx(inertia)
    assert result.coefficients["b1"] == pytest.approx(0.3 * inertia)
    assert result.added_inertia_fraction == pytest.approx((inertia - 1.2) / 1.2)
