"""What people report from a decay fit: period, damping ratio, B_eq(phi_a), Bertin N, extinction curve.

Formulas from ITTC 7.5-02-07-04.5 (reference §2): equivalent linear damping by
equal energy per cycle (eq. 13/15), Bertin's N (eq. 18; "Bertin N", unrelated
to the seeds' N), the extinction curve from successive peaks, and dimensional
coefficients once Delta*GM fixes the inertia scale (§5); full scale is ``ident.full_scale``. Uncertainties of
derived quantities come from the coefficient covariance by the delta method.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from ..physics.ikeda import hat_factor
from ..records import DecayRun
from .signals import half_cycle_peaks

G = 9.81


def linear_stiffness(coefficients: Mapping[str, float]) -> float:
    """Restoring slope at equilibrium, c1 + s1 (= omega_0^2)."""
    return coefficients.get("c1", 0.0) + coefficients.get("s1", 0.0)


def natural_frequency(coefficients: Mapping[str, float]) -> float:
    """Undamped natural frequency omega_0 in rad/s (NaN without positive stiffness)."""
    k = linear_stiffness(coefficients)
    return math.sqrt(k) if k > 0 else math.nan


def natural_period(coefficients: Mapping[str, float]) -> float:
    return 2.0 * math.pi / natural_frequency(coefficients)


def damping_ratio(coefficients: Mapping[str, float]) -> float:
    """Linear damping ratio zeta = b1 / (2 omega_0)."""
    return coefficients.get("b1", 0.0) / (2.0 * natural_frequency(coefficients))


#: cos(alpha) over a cycle (256 points) for the describing function, which B_eq bands call thousands of times.
_COS_ALPHA = np.cos(np.linspace(0.0, 2.0 * math.pi, 257)[:-1])


def equivalent_frequency(coefficients: Mapping[str, float], amplitude: float) -> float:
    """omega_eq(phi_a) of the restoring by the describing function (ITTC eq. 14), rad/s.

    The first Fourier coefficient of r(phi_a cos a) over phi_a: for c3 x^3 it adds
    (3/4) c3 phi_a^2; the sine terms are integrated numerically. Even terms drop out.
    """
    if amplitude > 0:
        k_eq = float(np.mean(_restoring(coefficients, amplitude * _COS_ALPHA) * _COS_ALPHA)) * 2.0 / amplitude
    else:
        k_eq = linear_stiffness(coefficients)
    return math.sqrt(k_eq) if k_eq > 0 else math.nan


def _equivalent_frequencies(coefficients: Mapping[str, float], amplitudes: np.ndarray) -> np.ndarray:
    """``equivalent_frequency`` at many amplitudes (rad) in one pass, a row of the cycle per amplitude."""
    moving = amplitudes > 0
    k_eq = np.full(amplitudes.shape, linear_stiffness(coefficients))
    x = amplitudes[moving, None] * _COS_ALPHA
    k_eq[moving] = np.mean(_restoring(coefficients, x) * _COS_ALPHA, axis=1) * 2.0 / amplitudes[moving]
    return np.sqrt(np.where(k_eq > 0, k_eq, np.nan))


def _restoring(coefficients: Mapping[str, float], x: np.ndarray) -> np.ndarray:
    """The restoring terms' r(x) at the angles ``x`` (any shape); even terms are left out (they drop
    out of the describing function)."""
    restoring = coefficients.get("c1", 0.0) * x
    if "c3" in coefficients:  # an absent term adds exact zeros: skipping it changes nothing but the time
        restoring = restoring + coefficients["c3"] * x**3
    if "s1" in coefficients or "s3" in coefficients:
        sin_x = np.sin(x)
        restoring = restoring + coefficients.get("s1", 0.0) * sin_x + coefficients.get("s3", 0.0) * sin_x**3
    return restoring


def b_eq(coefficients: Mapping[str, float], amplitude: float) -> float:
    """Equivalent linear damping per unit inertia at amplitude phi_a (rad), 1/s (ITTC eq. 15 / I).

    Uses omega_E = omega_eq(phi_a); ``mu_eq = b_eq / 2``.
    """
    return _b_eq_at(coefficients, equivalent_frequency(coefficients, amplitude), amplitude)


def _b_eqs(coefficients: Mapping[str, float], amplitudes: np.ndarray) -> np.ndarray:
    """``b_eq`` at many amplitudes (rad) in one pass."""
    return _b_eq_at(coefficients, _equivalent_frequencies(coefficients, amplitudes), amplitudes)


def _b_eq_at(coefficients: Mapping[str, float], omega: Any, amplitude: Any) -> Any:
    """ITTC eq. 15 / I at equivalent frequency ``omega`` and amplitude (floats, or arrays alike)."""
    return (
        coefficients.get("b1", 0.0)
        + 8.0 / (3.0 * math.pi) * omega * amplitude * coefficients.get("b2", 0.0)
        + 0.75 * (omega * amplitude) ** 2 * coefficients.get("b3", 0.0)
    )


def b_eq_band(
    coefficients: Mapping[str, float], covariance: np.ndarray, amplitudes_deg: Sequence[float] | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """B_eq (1/s) and its delta-method standard deviation at many amplitudes (deg): the ``b_eq`` and
    ``b_eq_std`` of ``amplitude_table``, for a plotted band, in one array pass per coefficient step
    instead of one describing function per amplitude and step (a report's band drew in 0.9 s)."""
    amplitudes = np.radians(np.asarray(amplitudes_deg, dtype=float))
    grad = _central_gradient(partial(_b_eqs, amplitudes=amplitudes), coefficients)
    variance = np.einsum("pn,pq,qn->n", grad, covariance, grad)
    return _b_eqs(coefficients, amplitudes), np.sqrt(np.maximum(variance, 0.0))


def bertin_n_per_deg(coefficients: Mapping[str, float], amplitude: float) -> float:
    """Bertin N per degree (MSC.1/Circ.1200) at amplitude phi_a: mu_eq = N phi_a omega / pi (eq. 18)."""
    if amplitude <= 0:
        return math.nan
    mu = 0.5 * b_eq(coefficients, amplitude)
    n_per_rad = math.pi * mu / (amplitude * equivalent_frequency(coefficients, amplitude))
    return n_per_rad * math.pi / 180.0


def delta_method(
    fn: Callable[[Mapping[str, float]], float], coefficients: Mapping[str, float], covariance: np.ndarray
) -> float:
    """Standard deviation of fn(coefficients) from the coefficient covariance (central differences)."""
    grad = _central_gradient(fn, coefficients)
    return float(math.sqrt(max(grad @ covariance @ grad, 0.0)))


def _central_gradient(
    fn: Callable[[Mapping[str, float]], float | np.ndarray], coefficients: Mapping[str, float]
) -> np.ndarray:
    """d fn / d coefficient by central differences, one row per coefficient (fn may return an array)."""
    names = list(coefficients)
    values = np.array([coefficients[k] for k in names])
    rows = []
    for i, value in enumerate(values):
        step = 1e-6 * max(abs(value), 1e-3)
        up, down = values.copy(), values.copy()
        up[i] += step
        down[i] -= step
        rows.append(
            (np.asarray(fn(dict(zip(names, up, strict=True)))) - fn(dict(zip(names, down, strict=True))))
            / (2 * step)
        )
    return np.array(rows)


@dataclass
class AmplitudePoint:
    """B_eq and friends at one amplitude, with their delta-method standard deviations."""

    amplitude_deg: float
    b_eq: float
    b_eq_std: float
    mu_eq: float
    bertin_n_per_deg: float
    bertin_n_std: float


def amplitude_table(
    coefficients: Mapping[str, float], covariance: np.ndarray, amplitudes_deg: Sequence[float]
) -> list[AmplitudePoint]:
    """B_eq(phi_a), mu_eq and Bertin N over the amplitudes (deg), with uncertainty."""
    out = []
    for a_deg in amplitudes_deg:
        a = math.radians(a_deg)
        value = b_eq(coefficients, a)
        n = bertin_n_per_deg(coefficients, a)
        out.append(
            AmplitudePoint(
                amplitude_deg=float(a_deg),
                b_eq=value,
                b_eq_std=delta_method(partial(b_eq, amplitude=a), coefficients, covariance),
                mu_eq=0.5 * value,
                bertin_n_per_deg=n,
                bertin_n_std=delta_method(partial(bertin_n_per_deg, amplitude=a), coefficients, covariance),
            )
        )
    return out


def tested_amplitudes_deg(runs: Sequence[DecayRun], offsets: Sequence[float], count: int = 5) -> list[float]:
    """A grid over the amplitude band the runs covered (smallest meaningful to largest peak), deg."""
    peaks = np.concatenate(
        [
            np.abs((run.angle - off)[half_cycle_peaks(run.angle - off)])
            for run, off in zip(runs, offsets, strict=True)
        ]
    )
    if peaks.size == 0:
        return []
    # Peaks lost in the sensor noise at the end of a decay are not a tested amplitude: the band
    # runs down to 0.5 deg (where ITTC stops a decay), or 20 % of the largest peak if that is lower.
    top = float(peaks.max())
    bottom = float(peaks[peaks >= min(math.radians(0.5), 0.2 * top)].min())
    return [round(math.degrees(a), 2) for a in np.linspace(bottom, top, count)]


@dataclass
class ExtinctionCurve:
    """Measured decrement per half-cycle against mean amplitude, and the model's curve (rad)."""

    mean_amplitude: np.ndarray
    decrement: np.ndarray
    model_amplitude: np.ndarray
    model_decrement: np.ndarray


def extinction_curve(
    runs: Sequence[DecayRun], offsets: Sequence[float], coefficients: Mapping[str, float]
) -> ExtinctionCurve:
    """Decrement phi_n - phi_(n+1) vs mean amplitude phi_m of successive peaks, and the model's curve.

    The model: a phi + b phi^2 + c phi^3 with a = pi mu / omega, b = 4 beta / 3,
    c = 3 pi delta omega / 8 (reference §2, from the half-cycle energy balance).
    An intercept of the measured points at phi_m -> 0 means friction.
    """
    means, decrements = [], []
    for run, off in zip(runs, offsets, strict=True):
        y = run.angle - off
        peaks = np.abs(y[half_cycle_peaks(y)])
        means.append(0.5 * (peaks[:-1] + peaks[1:]))
        decrements.append(peaks[:-1] - peaks[1:])
    mean_amplitude = np.concatenate(means) if means else np.zeros(0)
    omega = natural_frequency(coefficients)
    grid = np.linspace(0.0, float(mean_amplitude.max()) if mean_amplitude.size else 0.0, 50)
    model = (
        math.pi * 0.5 * coefficients.get("b1", 0.0) / omega * grid
        + 4.0 / 3.0 * coefficients.get("b2", 0.0) * grid**2
        + 3.0 * math.pi / 8.0 * coefficients.get("b3", 0.0) * omega * grid**3
    )
    return ExtinctionCurve(
        mean_amplitude, np.concatenate(decrements) if decrements else np.zeros(0), grid, model
    )


@dataclass
class Dimensional:
    """Dimensional results once Delta*GM fixes the inertia scale (SI: kg m^2, N m s/rad ...)."""

    total_inertia_kg_m2: float
    coefficients: dict[str, float]  # every term times the total inertia
    added_inertia_fraction: float | None  # (I_total - I_dry) / I_dry when the dry inertia is known


def dimensional(
    coefficients: Mapping[str, float],
    displacement_kg: float,
    gm_m: float,
    dry_inertia_kg_m2: float | None = None,
) -> Dimensional:
    """I = Delta g GM / (c1 + s1); B1 = b1 I, C3 = c3 I ... (reference §5)."""
    inertia = displacement_kg * G * gm_m / linear_stiffness(coefficients)
    added = (inertia - dry_inertia_kg_m2) / dry_inertia_kg_m2 if dry_inertia_kg_m2 else None
    return Dimensional(inertia, {k: v * inertia for k, v in coefficients.items()}, added)


def b44_hat_factor(hull: Any, draft: float = 1.0) -> float | None:
    """B̂44 per B44 (per N·m·s): √(B/2g) / (ρ ∇ B²) with ∇ = m / ρ from the hull's displacement (scaled
    with the draft factor, as ``dimensional`` is) and its beam; None where the hull lacks either."""
    particulars = hull.main_particulars.at(draft)
    beam = particulars.get("beam_m", hull.dimensions.get("beam_m"))
    if beam is None or hull.displacement_kg is None:
        return None
    return hat_factor(beam, hull.displacement_kg * draft, G)  # rho * volume = the displacement
