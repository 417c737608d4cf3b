"""Residual diagnostics on signals whose answer is known by construction."""

from __future__ import annotations

import numpy as np
import pytest

from tankdaq.diagnose.residuals import (
    channel_correlation,
    cycle_trend,
    late_onset,
    residual_spectrum,
)
from tankdaq.physics.decay import simulate_decay

RATE_HZ = 100.0
T = np.arange(1500) / RATE_HZ


@pytest.mark.parametrize(
    ("omega_factor", "location"), [(1.0, "natural"), (2.0, "double"), (3.0, "triple"), (1.6, "other")]
)
def test_spectrum_names_where_the_residual_lives(omega_factor: float, location: str) -> None:
    rng = np.random.default_rng(3)
    omega0 = 3.0
    residuals = [
        0.01 * np.sin(omega_factor * omega0 * T + phase) + rng.normal(0, 0.001, T.size) for phase in (0, 1, 2)
    ]
    spec = residual_spectrum(residuals, RATE_HZ, omega0)
    assert spec.location == location
    assert spec.peak_rad_s == pytest.approx(omega_factor * omega0, abs=0.6)


def test_spectrum_of_white_noise_has_no_peak_and_an_offset_sits_at_zero() -> None:
    rng = np.random.default_rng(4)
    assert residual_spectrum([rng.normal(0, 1e-3, T.size) for _ in range(3)], RATE_HZ, 3.0).location == "none"
    offset = [0.01 + rng.normal(0, 1e-3, T.size) for _ in range(3)]
    assert residual_spectrum(offset, RATE_HZ, 3.0).location == "zero"


def test_cycle_trend_sees_amplitude_dependent_damping_and_period() -> None:
    angles = (0.4, 0.25, 0.12)
    linear = [simulate_decay({"b1": 0.2, "c1": 10.0}, T, a)[0] for a in angles]
    quadratic = [simulate_decay({"b1": 0.1, "b2": 0.4, "c1": 10.0}, T, a)[0] for a in angles]
    stiffening = [simulate_decay({"b1": 0.2, "c1": 10.0, "c3": 15.0}, T, a)[0] for a in angles]
    omega0 = np.sqrt(10.0)
    flat = cycle_trend([T] * 3, linear, omega0)
    assert not flat.damping_grows_with_amplitude and not flat.period_changes_with_amplitude
    assert flat.zeta_intercept == pytest.approx(0.2 / (2 * omega0), rel=0.05)
    grows = cycle_trend([T] * 3, quadratic, omega0)
    assert grows.damping_grows_with_amplitude
    # ITTC eq. 13 with unit inertia: d(zeta)/d(amplitude) = 4 b2 / (3 pi)
    assert grows.zeta_slope_per_rad == pytest.approx(4 * 0.4 / (3 * np.pi), rel=0.15)
    stiff = cycle_trend([T] * 3, stiffening, omega0)
    assert stiff.period_changes_with_amplitude and stiff.period_slope_s_per_rad2 < 0


def test_late_onset_finds_a_burst_that_grows_from_nothing() -> None:
    rng = np.random.default_rng(5)
    onset = 9.0
    burst = 0.004 * np.clip(T - onset, 0.0, None) * np.sin(3.0 * (T - onset))  # zero before the onset
    found = late_onset(T, rng.normal(0, 0.001, T.size) + burst)
    assert onset - 1.0 <= found.onset_s <= onset + 0.8
    assert found.ratio > 3
    quiet = late_onset(T, rng.normal(0, 0.001, T.size))
    assert quiet.ratio < 1.5


def test_channel_correlation_sees_a_shifted_copy() -> None:
    rng = np.random.default_rng(6)
    heave = np.sin(5.0 * T)
    residual = 0.3 * np.roll(heave, 12) + rng.normal(0, 0.1, T.size)
    assert channel_correlation(residual, heave, max_lag=30) > 0.8
    assert channel_correlation(rng.normal(size=T.size), heave, max_lag=30) < 0.15
