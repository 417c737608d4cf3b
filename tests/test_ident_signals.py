"""The Savitzky-Golay derivatives the equation-error fit starts from, against scipy.signal's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_filter

from tankdaq.ident.signals import smoothed_derivatives


@pytest.mark.parametrize(("n", "window", "dt"), [(1500, 25, 0.01), (300, 7, 0.0025), (50, 9, 0.1)])
def test_smoothed_derivatives_are_scipys_savgol_filter(n: int, window: int, dt: float) -> None:
    """Same value, slope and curvature as ``savgol_filter(mode="nearest")``, to rounding."""
    rng = np.random.default_rng(window)
    t = np.arange(n) * dt
    y = np.sin(3.0 * t) * np.exp(-0.2 * t) + rng.normal(0.0, 1e-3, n)
    for deriv, mine in enumerate(smoothed_derivatives(y, dt, window, polyorder=3)):
        expected = savgol_filter(y, window, 3, deriv=deriv, delta=dt, mode="nearest")
        np.testing.assert_allclose(mine, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))
