"""Where and how a fitted decay disagrees with the measurement: residual and model-free diagnostics.

Each function answers one question a lab engineer asks of a residual: at
what frequency does it live (Welch), does damping or the period change with
amplitude (cycle-by-cycle peaks), does it start late (a change point in its
variance: reflected tank waves), does it follow another measured channel
(coupling). Whiteness (Ljung-Box) and the noise level are ident's
(``ident.uncertainty.ljung_box``, ``ident.signals.white_noise_level``). The
selection itself is decided by refits; these diagnostics say why, and name the
signature in the report.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import find_peaks, welch
from scipy.stats import theilslopes


@dataclass
class Spectrum:
    """Welch spectrum of the residual and where its main peak sits relative to the natural frequency."""

    omega_rad_s: np.ndarray
    psd: np.ndarray
    peak_rad_s: float
    peak_prominence: float  # peak PSD / median PSD: ~1-3 for white noise
    location: str  # "none", "zero", "natural", "double", "triple", "other"


def residual_spectrum(
    residuals: Sequence[np.ndarray], rate_hz: float, omega0_rad_s: float, padding: int = 1
) -> Spectrum:
    """Run-averaged Welch PSD of the residual; segments of about four natural periods. ``padding``
    zero-pads each segment that many times (a figure's smooth curve; the resolution, and so where a
    peak is said to sit, is the segments')."""
    period_samples = int(2 * np.pi / max(omega0_rad_s, 1e-3) * rate_hz)
    shortest = min(e.size for e in residuals)
    nperseg = int(min(shortest, max(4 * period_samples, 64)))
    spectra = [
        welch(np.asarray(e, dtype=float), fs=rate_hz, nperseg=nperseg, nfft=padding * nperseg, detrend=False)
        for e in residuals
    ]
    omega = 2 * np.pi * spectra[0][0]
    psd_mean = np.mean([psd for _, psd in spectra], axis=0)
    band = omega <= 6 * omega0_rad_s  # the physics lives here; above is sensor noise
    i_peak = int(np.argmax(np.where(band, psd_mean, -np.inf)))
    floor = float(np.median(psd_mean[omega > 0])) or 1e-300
    prominence = float(psd_mean[i_peak] / floor)
    return Spectrum(
        omega,
        psd_mean,
        float(omega[i_peak]),
        prominence,
        _locate(omega[i_peak], omega0_rad_s, prominence, 2 * np.pi * rate_hz / nperseg),
    )


def _locate(peak: float, omega0: float, prominence: float, resolution: float) -> str:
    if prominence < 10:
        return "none"
    if peak <= max(0.3 * omega0, resolution):
        return "zero"
    ratio = peak / omega0
    for label, centre in (("natural", 1.0), ("double", 2.0), ("triple", 3.0)):
        if abs(ratio - centre) <= max(0.2, 1.5 * resolution / omega0):
            return label
    return "other"


SPECTRUM_MEANING = {
    "none": "no spectral peak (white)",
    "zero": "peak near zero frequency: offset, bias or drift",
    "natural": "peak at the natural frequency: damping or stiffness mis-modelled",
    "double": "peak at twice the natural frequency: asymmetry or coupling to a motion at 2w",
    "triple": "peak at three times the natural frequency: a cubic term",
    "other": "peak at another frequency: coupling with another motion or a disturbance",
}


@dataclass
class CycleTrend:
    """Cycle-by-cycle damping ratio and period against amplitude (model-free, offset-free)."""

    amplitude_rad: np.ndarray
    zeta: np.ndarray
    period_s: np.ndarray
    zeta_slope_per_rad: float  # d(zeta)/d(amplitude)
    zeta_intercept: float
    period_slope_s_per_rad2: float  # d(period)/d(amplitude^2)

    def _zeta_change(self) -> float:
        """Change of ζ over the tested amplitude band, relative to its median (0 with too few cycles)."""
        if self.amplitude_rad.size < 3:
            return 0.0
        span = float(np.ptp(self.amplitude_rad))
        return self.zeta_slope_per_rad * span / max(abs(float(np.median(self.zeta))), 1e-6)

    @property
    def damping_grows_with_amplitude(self) -> bool:
        """ζ rising by more than a quarter over the tested amplitude band."""
        return self._zeta_change() > 0.25

    @property
    def damping_falls_with_amplitude(self) -> bool:
        """ζ falling by more than a quarter over the band: dry friction dominates small cycles."""
        return self._zeta_change() < -0.25

    @property
    def period_changes_with_amplitude(self) -> bool:
        """Period changing by more than 1 % over the tested amplitude band (damping alone moves it less)."""
        if self.amplitude_rad.size < 3:
            return False
        span = float(np.ptp(self.amplitude_rad**2))
        return abs(self.period_slope_s_per_rad2) * span > 0.01 * float(np.median(self.period_s))


def alternating_extremes(angle: np.ndarray, min_spacing: int) -> np.ndarray:
    """Indices of maxima and minima in strict alternation (of two same-sign neighbours the larger stays)."""
    hi, _ = find_peaks(angle, distance=min_spacing)
    lo, _ = find_peaks(-angle, distance=min_spacing)
    maxima = set(hi.tolist())
    kept: list[int] = []
    signs: list[int] = []
    for i in sorted([*hi.tolist(), *lo.tolist()]):
        sign = 1 if i in maxima else -1
        if signs and signs[-1] == sign:
            if sign * angle[i] > sign * angle[kept[-1]]:
                kept[-1] = i
            continue
        kept.append(i)
        signs.append(sign)
    return np.asarray(kept, dtype=int)


def cycle_trend(
    runs_t: Sequence[np.ndarray], runs_angle: Sequence[np.ndarray], omega0_rad_s: float
) -> CycleTrend:
    """Peaks of every run pooled: ζ_n = ln(D_n / D_{n+2}) / 2π on peak-to-peak heights D (offset-free).

    Trends are Theil-Sen slopes: a small cycle spoiled by noise does not tip them.
    """
    amps, zetas, periods = [], [], []
    half_period = np.pi / max(omega0_rad_s, 1e-3)
    for t, angle in zip(runs_t, runs_angle, strict=True):
        dt = float(np.median(np.diff(t)))
        idx = alternating_extremes(angle, max(int(1.2 * half_period / dt), 1))
        if idx.size < 4:
            continue
        heights = np.abs(np.diff(angle[idx]))  # peak-to-peak, one per half cycle
        times = t[idx]
        for n in range(heights.size - 2):
            if heights[n + 2] <= 0 or heights[n] <= heights[n + 2]:
                continue
            amps.append(0.25 * (heights[n] + heights[n + 2]))
            zetas.append(np.log(heights[n] / heights[n + 2]) / (2 * np.pi))
            periods.append(float(times[n + 2] - times[n]))
    amp = np.asarray(amps)
    zeta = np.asarray(zetas)
    period = np.asarray(periods)
    if amp.size >= 3 and np.ptp(amp) > 0:
        zeta_slope, zeta_intercept, _, _ = theilslopes(zeta, amp)
        period_slope = float(theilslopes(period, amp**2)[0])
    else:
        zeta_slope, zeta_intercept, period_slope = 0.0, float(np.mean(zeta)) if zeta.size else 0.0, 0.0
    return CycleTrend(amp, zeta, period, float(zeta_slope), float(zeta_intercept), period_slope)


@dataclass
class LateOnset:
    """A change point in the residual's variance: quiet before ``onset_s``, loud after."""

    onset_s: float  # time from the start of the run
    rms_before: float
    rms_after: float

    @property
    def ratio(self) -> float:
        return self.rms_after / max(self.rms_before, 1e-300)


def late_onset(t: np.ndarray, residual: np.ndarray, min_fraction: float = 0.3) -> LateOnset:
    """Where the residual turns from noise into a burst.

    The split that best explains the residual as two segments of different
    variance (Gaussian likelihood), moved back to the minimum of the CUSUM of
    e^2 minus the quiet variance before it: a resonant disturbance grows from
    nothing, and the variance split alone finds it a second or two late.
    """
    e2 = np.asarray(residual, dtype=float) ** 2
    n = e2.size
    csum = np.cumsum(e2)
    idx = np.arange(max(int(min_fraction * n), 1), int(0.95 * n))
    if idx.size == 0:
        rms = float(np.sqrt(np.mean(e2)))
        return LateOnset(float(t[-1] - t[0]), rms, rms)
    var_before = csum[idx - 1] / idx
    var_after = (csum[-1] - csum[idx - 1]) / (n - idx)
    cost = idx * np.log(var_before + 1e-300) + (n - idx) * np.log(var_after + 1e-300)
    split = int(idx[np.argmin(cost)])
    cusum = np.cumsum(e2 - var_before[split - idx[0]])
    onset = int(idx[0]) + int(np.argmin(cusum[idx[0] : split + 1]))
    before = float(np.sqrt(csum[onset - 1] / onset))
    after = float(np.sqrt((csum[-1] - csum[onset - 1]) / (n - onset)))
    return LateOnset(float(t[onset] - t[0]), before, after)


def channel_correlation(residual: np.ndarray, channel: np.ndarray, max_lag: int) -> float:
    """Largest |normalised cross-correlation| of residual and channel within ±max_lag samples."""
    e = np.asarray(residual, dtype=float) - np.mean(residual)
    u = np.asarray(channel, dtype=float) - np.mean(channel)
    denom = float(np.linalg.norm(e) * np.linalg.norm(u))
    if denom == 0.0:
        return 0.0
    best = 0.0
    for lag in range(-max_lag, max_lag + 1):
        c = float(np.dot(e[lag:], u[: u.size - lag])) if lag >= 0 else float(np.dot(e[:lag], u[-lag:]))
        best = max(best, abs(c) / denom)
    return best


def ringing_frequency(residuals: Sequence[np.ndarray], rate_hz: float, omega0_rad_s: float) -> float | None:
    """The frequency of a motion the residual rings with that is no harmonic of the decay (None if none).

    A zero-padded periodogram summed over runs resolves it far finer than Welch
    segments, as an unmeasured coupling's refit needs a start within a fraction
    of 2*pi / record length. Zero, the natural frequency and its harmonics (+-15 %)
    are left out: those are other effects' signatures.
    """
    omega, power = _periodogram(residuals, rate_hz)
    ratio = omega / omega0_rad_s
    allowed = (ratio > 0.3) & (ratio < 6.0) & (np.abs(ratio - np.round(ratio)) > 0.15)
    floor = float(np.median(power[omega > 0]))
    if not np.any(allowed) or floor == 0.0:
        return None
    i_peak = int(np.argmax(np.where(allowed, power, -np.inf)))
    return float(omega[i_peak]) if power[i_peak] > 50 * floor else None


def swing_frequency(series: Sequence[np.ndarray], rate_hz: float) -> float:
    """The frequency (rad/s) the series swing at most: the peak of their summed periodogram."""
    omega, power = _periodogram(series, rate_hz)
    return float(omega[1 + int(np.argmax(power[1:]))])


def _periodogram(series: Sequence[np.ndarray], rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(omega rad/s, power) of the series zero-padded 8 times, each less its mean, the powers summed."""
    n_fft = 8 * max(np.asarray(x).size for x in series)
    power = np.sum([np.abs(np.fft.rfft(np.asarray(x) - np.mean(x), n_fft)) ** 2 for x in series], axis=0)
    return 2 * np.pi * np.fft.rfftfreq(n_fft, 1.0 / rate_hz), power


@dataclass
class Diagnostics:
    """What the residual of one fit says."""

    rms_angle_rad: float
    noise_angle_rad: float
    ljung_box_p: float
    spectrum: Spectrum
    residual_mean_angle_rad: float
    residual_mean_rate_rad_s: float | None
    noise_rate_rad_s: float | None
    corr_with_rate: float  # angle residual vs predicted rate: lag signature
    corr_with_angle: float  # angle residual vs predicted angle: gain signature
    channel_corr: dict[str, float]
    late: list[LateOnset]
    ringing_rad_s: float | None  # a non-harmonic frequency the residual rings with

    @property
    def white(self) -> bool:
        return self.ljung_box_p > 0.01
