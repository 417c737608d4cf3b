"""The signal helpers against scipy's own: the Savitzky-Golay derivatives the equation-error fit starts
from (scipy.signal), the running spread and mean that find where a model rests (scipy.ndimage)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import maximum_filter1d, minimum_filter1d, uniform_filter1d
from scipy.signal import savgol_filter

from tankdaq.ident.signals import running_mean, running_range, smoothed_derivatives, white_noise_level
from tankdaq.physics.decay import simulate_decay


@pytest.mark.parametrize(("n", "window", "dt"), [(1500, 25, 0.01), (300, 7, 0.0025), (50, 9, 0.1)])
def test_smoothed_derivatives_are_scipys_savgol_filter(n: int, window: int, dt: float) -> None:
    """Same value, slope and curvature as ``savgol_filter(mode="nearest")``, to rounding."""
    rng = np.random.default_rng(window)
    t = np.arange(n) * dt
    y = np.sin(3.0 * t) * np.exp(-0.2 * t) + rng.normal(0.0, 1e-3, n)
    for deriv, mine in enumerate(smoothed_derivatives(y, dt, window, polyorder=3)):
        expected = savgol_filter(y, window, 3, deriv=deriv, delta=dt, mode="nearest")
        np.testing.assert_allclose(mine, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))


@pytest.mark.parametrize(("n", "window"), [(9, 3), (10, 3), (40, 4), (1001, 64), (12345, 101), (5000, 250)])
def test_running_spread_and_mean_are_scipy_ndimages_filters(n: int, window: int) -> None:
    """Centred windows, odd and even, the ends mirrored as ``mode="reflect"``: the spread exactly,
    the mean to rounding (a running sum here, scipy's own there)."""
    y = np.random.default_rng(n).normal(0.0, 0.01, n).cumsum()
    spread = maximum_filter1d(y, window) - minimum_filter1d(y, window)
    np.testing.assert_array_equal(running_range(y, window), spread)
    expected = uniform_filter1d(y, window)
    np.testing.assert_allclose(running_mean(y, window), expected, rtol=0, atol=1e-12 * np.max(np.abs(y)))


def test_white_noise_level_recovers_white_noise_on_a_decay() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(1500) / 100.0
    angle, _ = simulate_decay({"b1": 0.2, "c1": 10.0}, t, 0.3)
    for sigma in (1e-4, 1e-3, 1e-2):
        assert white_noise_level(angle + rng.normal(0, sigma, t.size)) == pytest.approx(sigma, rel=0.08)
    # a quantised record (MAD of the third differences zero) falls back to their plain spread
    steps = np.round(angle / 0.05) * 0.05
    assert white_noise_level(steps) > 0
