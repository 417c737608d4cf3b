"""Signal helpers the estimators share: period, smoothed derivatives, noise level, half-cycles."""

from __future__ import annotations

import functools
import math

import numpy as np

from ..errors import BadIdentificationInput

#: Savitzky-Golay weight sets kept (window, order, derivative): a day's decays need a few dozen.
SAVGOL_CACHE = 128


def zero_crossings(y: np.ndarray) -> np.ndarray:
    """Indices i where y changes sign between i and i+1 (exact zeros count once)."""
    s = np.sign(y)
    s[s == 0] = 1.0
    return np.flatnonzero(s[1:] != s[:-1])


def band_crossings(y: np.ndarray, band: float) -> int:
    """Sign changes of y across the whole band [-band, band]: hysteresis, noise near zero does not count."""
    sides = np.sign(y[np.abs(y) > band])
    return int(np.count_nonzero(sides[1:] != sides[:-1]))


def estimate_period(t: np.ndarray, angle: np.ndarray) -> float:
    """Oscillation period from the mean spacing of zero crossings about the record's median.

    The median is a cheap stand-in for the equilibrium; a decay crosses it every
    half period. Raises when the record does not oscillate at least once.
    """
    crossings = zero_crossings(angle - np.median(angle[angle.size // 2 :]))
    if crossings.size < 2:
        raise BadIdentificationInput(
            "the record does not oscillate (fewer than two zero crossings): no decay to identify"
        )
    half_periods = np.diff(t[crossings])
    return float(2.0 * np.median(half_periods))


def savgol_window(dt: float, period_s: float, fraction: float, polyorder: int) -> int:
    """An odd Savitzky-Golay window of about ``fraction`` of a period, long enough for the order."""
    n = round(fraction * period_s / dt) | 1
    return max(n, polyorder + 3 | 1)


def smoothed_derivatives(
    y: np.ndarray, dt: float, window: int, polyorder: int = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Savitzky-Golay value, first and second derivative of a uniformly sampled signal.

    The first and last half-windows are only padded, not fitted: callers trim
    them (see ``start_state`` for the state at the first sample).
    """
    if y.size <= window:
        raise BadIdentificationInput(f"the record ({y.size} samples) is shorter than one smoothing window")
    padded = np.pad(y, window // 2, mode="edge")
    value, first, second = (
        np.correlate(padded, _savgol_weights(window, polyorder, d), mode="valid") / dt**d for d in range(3)
    )
    return value, first, second


@functools.lru_cache(maxsize=SAVGOL_CACHE)
def _savgol_weights(window: int, polyorder: int, deriv: int) -> np.ndarray:
    """Savitzky-Golay weights over a centred window: the ``deriv``-th derivative (per sample) at its centre.

    What scipy.signal.savgol_filter computes, without importing scipy.signal (about a second). Kept for
    the newest ``SAVGOL_CACHE`` windows: the window follows each decay's period, so a recorder's day
    meets new ones, and an unbounded cache grew by one entry every few decays.
    """
    half = window // 2
    powers = np.arange(-half, half + 1, dtype=float)[None, :] ** np.arange(polyorder + 1)[:, None]
    unit = np.zeros(polyorder + 1)
    unit[deriv] = math.factorial(deriv)
    return np.linalg.lstsq(powers, unit, rcond=None)[0]


def start_state(t: np.ndarray, y: np.ndarray, window: int, polyorder: int = 3) -> tuple[float, float]:
    """Value and slope at t[0] of a polynomial fitted to the first window: the smoothed initial state."""
    coef = np.polynomial.polynomial.polyfit(t[:window] - t[0], y[:window], polyorder)
    return float(coef[0]), float(coef[1])


def white_noise_level(y: np.ndarray) -> float:
    """Standard deviation of white noise on a smooth signal, from third differences (robust MAD).

    The third difference of white noise has variance 20 sigma^2 while a smooth
    oscillation sampled well above its frequency nearly cancels out (a decay at
    100 Hz keeps ~1e-5 of its amplitude). The MAD makes it robust to a release
    transient; a quantised signal (MAD = 0) falls back to the plain std; fewer
    than four third differences give 0.
    """
    d3 = np.diff(np.asarray(y, dtype=float), 3)
    if d3.size < 4:
        return 0.0
    mad = float(np.median(np.abs(d3 - np.median(d3))))
    spread = 1.4826 * mad if mad > 0 else float(np.std(d3))
    return spread / math.sqrt(20.0)


def half_cycle_peaks(y: np.ndarray) -> np.ndarray:
    """Index of the largest |y| in each complete half-cycle (not the first or last, which may be cut).

    A half-cycle is a stretch on one side of zero, with hysteresis: y must leave
    a band of 3 noise sigmas on the other side, so noise around a settled
    equilibrium does not make tiny half-cycles.
    """
    band = 3.0 * white_noise_level(y) if y.size > 3 else 0.0
    outside = np.flatnonzero(np.abs(y) > band)
    if outside.size == 0:
        return np.zeros(0, dtype=int)
    sides = np.sign(y[outside])
    switches = np.flatnonzero(sides[1:] != sides[:-1])
    starts = outside[np.concatenate([[0], switches + 1])]
    stops = np.concatenate([outside[switches], [outside[-1]]]) + 1
    return np.array(
        [a + int(np.argmax(np.abs(y[a:b]))) for a, b in zip(starts[1:-1], stops[1:-1], strict=True)],
        dtype=int,
    )


def _centred(y: np.ndarray, window: int) -> np.ndarray:
    """``y`` padded so that window ``i`` of the result is centred on sample ``i`` (``window // 2`` before
    it), the ends mirrored with their edge sample repeated: scipy.ndimage's ``reflect``."""
    return np.pad(y, (window // 2, window - 1 - window // 2), mode="symmetric")


def running_range(y: np.ndarray, window: int) -> np.ndarray:
    """The spread (max - min) of ``y`` over a centred window of ``window`` samples at each sample.

    numpy, not scipy.ndimage's filters: importing those is a third of a second of CPU in every
    command that reads a CSV."""
    padded = _centred(y, window)
    return _running_extreme(padded, window, np.maximum, y.size) - _running_extreme(
        padded, window, np.minimum, y.size
    )


def _running_extreme(padded: np.ndarray, window: int, extreme: np.ufunc, size: int) -> np.ndarray:
    """``extreme`` (np.maximum or np.minimum) over each run of ``window`` samples of ``padded``, O(n) for
    any window (van Herk / Gil-Werman): cut into blocks of ``window``, a run spans the end of one block
    and the start of the next, so its extreme is that of a block's suffix and of the next one's prefix."""
    blocks = -(-padded.size // window)
    fill = -np.inf if extreme is np.maximum else np.inf
    full = np.concatenate([padded, np.full(blocks * window - padded.size, fill)]).reshape(blocks, window)
    prefix = extreme.accumulate(full, axis=1).ravel()
    suffix = extreme.accumulate(full[:, ::-1], axis=1)[:, ::-1].ravel()
    return extreme(suffix[:size], prefix[window - 1 : window - 1 + size])


def running_mean(y: np.ndarray, window: int) -> np.ndarray:
    """The mean of ``y`` over a centred window of ``window`` samples at each sample (ends mirrored)."""
    sums = np.concatenate([[0.0], np.cumsum(_centred(y, window), dtype=float)])
    return (sums[window:] - sums[:-window]) / window
