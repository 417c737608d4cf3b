"""The canonical 1-DOF decay equation, per unit total inertia, angles in rad.

    x'' + b1 x' + b2 |x'| x' + b3 x'^3 + c1 x + c2 x^2 + c3 x^3
        + s1 sin x + s2 sin^2 x + s3 sin^3 x = 0

The term names b1 b2 b3 c1 c2 c3 s1 s2 s3 are tankdaq's public vocabulary (CLI,
JSON, files); their labels and units are in the one term table, ``physics.terms``.
Only ratios to the total inertia are identifiable from a free decay, so every
coefficient here is already divided by it (units s^-1, rad^-1, s rad^-2 for
damping; s^-2 ... for restoring).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from .terms import RESTORING_TERMS, TERMS, terms_of_kind

DAMPING_TERMS: tuple[str, ...] = terms_of_kind("damping")


def _term_values(x: Any, v: Any, sin: Callable[[Any], Any]) -> dict[str, Any]:
    """Each term's function of state: the one table, for arrays (``np.sin``) and for floats
    (``math.sin``)."""
    sx = sin(x)
    return {
        "b1": v,
        "b2": abs(v) * v,
        "b3": v**3,
        "c1": x,
        "c2": x**2,
        "c3": x**3,
        "s1": sx,
        "s2": sx**2,
        "s3": sx**3,
    }


def regressors(angle: np.ndarray, rate: np.ndarray, terms: Sequence[str] = TERMS) -> np.ndarray:
    """The value of each term's function of state, shape (n, len(terms)).

    The equation reads ``x'' = -regressors @ coefficients``.
    """
    x = np.asarray(angle, dtype=float)
    v = np.asarray(rate, dtype=float)
    table = _term_values(x, v, np.sin)
    unknown = [name for name in terms if name not in table]
    if unknown:
        raise KeyError(f"unknown decay term(s) {unknown}; known: {', '.join(TERMS)}")
    return np.column_stack([table[name] for name in terms]) if terms else np.zeros((x.size, 0))


def terms_sum(coefficients: Mapping[str, float]) -> Callable[[float, float], float]:
    """The damping and restoring per unit inertia, ``(x, v) -> regressors @ coefficients``, for one
    state in floats: what a reference integrator calls thousands of times a decay (numpy's per-call
    cost is ten times the arithmetic's). Missing terms are zero."""
    pairs = [(name, float(coefficients[name])) for name in TERMS if coefficients.get(name, 0.0) != 0.0]

    def total(x: float, v: float) -> float:
        values = _term_values(x, v, math.sin)
        return sum((value * values[name] for name, value in pairs), 0.0)  # a float with no terms too

    return total


def acceleration(coefficients: Mapping[str, float], angle: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """x'' for the given state under the given coefficients (missing terms are zero)."""
    names = [k for k in TERMS if coefficients.get(k, 0.0) != 0.0]
    theta = np.array([coefficients[k] for k in names], dtype=float)
    return -(regressors(angle, rate, names) @ theta) if names else np.zeros(np.shape(angle))


def linear_stiffness(coefficients: Mapping[str, float]) -> float:
    """d(restoring)/dx at x = 0: c1 + s1. Its square root is the undamped natural frequency."""
    return float(coefficients.get("c1", 0.0) + coefficients.get("s1", 0.0))


#: The simulator releases at most 30 deg (a scripted wrong angle included); its coefficients are checked a
#: little beyond, so the hand's scatter at release stays inside what was checked.
PLAYED_ANGLE_RAD = math.radians(36.0)
#: Below this amplitude a decay has settled for the release detector (its settle default is 0.5 deg).
SETTLED_ANGLE_RAD = math.radians(0.2)
#: Natural periods the simulator plays: a scenario gives each run 25 s of decay, and a release needs
#: oscillations the detector can count.
PLAYABLE_PERIOD_S = (0.2, 30.0)
#: Samples per natural period at the output rate, at the least (fewer: the swings are not seen).
MIN_SAMPLES_PER_PERIOD = 10
#: No term may exceed this multiple of the linear restoring at the largest state played: beyond it the
#: adaptive integration takes steps far shorter than a sample (hours per decay) for no physics a tank sees.
MAX_TERM_RATIO = 100.0


def decay_refusal(coefficients: Mapping[str, float], rate_hz: float | None = None) -> str | None:
    """Why these coefficients do not give a decay the simulator can play (None: they do).

    A decay: every value finite; a positive linear stiffness (c1 + s1) and a restoring that stays
    positive up to ``PLAYED_ANGLE_RAD``; damping (b1 x' + b2|x'|x' + b3 x'^3) that takes energy out at
    every speed from a settled to the largest swing (a negative b1 makes small swings grow: the decay
    never settles); under-damped at small amplitude (b1 < 2 omega0: it swings); a natural period in
    ``PLAYABLE_PERIOD_S`` and of at least ``MIN_SAMPLES_PER_PERIOD`` samples at ``rate_hz``; no term
    beyond ``MAX_TERM_RATIO`` times the linear restoring at the largest state.
    """
    values = {name: float(value) for name, value in coefficients.items()}
    not_finite = [name for name, value in values.items() if not math.isfinite(value)]
    if not_finite:
        return f"{', '.join(not_finite)} not finite"
    stiffness = linear_stiffness(values)
    if not stiffness > 0:
        return f"the linear stiffness c1 + s1 = {stiffness:g} 1/s^2 is not positive (the model capsizes)"
    omega = math.sqrt(stiffness)
    period_s = 2 * math.pi / omega
    low, high = PLAYABLE_PERIOD_S
    if not low <= period_s <= high:
        return f"the natural period {period_s:.3g} s is outside the {low:g}..{high:g} s the simulator plays"
    if rate_hz is not None and period_s * rate_hz < MIN_SAMPLES_PER_PERIOD:
        return (
            f"the natural period {period_s:.3g} s is {period_s * rate_hz:.1f} samples at {rate_hz:g} Hz "
            f"(at least {MIN_SAMPLES_PER_PERIOD}): give a faster rate"
        )
    return _restoring_refusal(values, stiffness) or _damping_refusal(values, omega)


def _restoring_refusal(values: Mapping[str, float], stiffness: float) -> str | None:
    """The restoring pushes back towards upright at every angle played, and is not absurdly stiff."""
    x = np.linspace(-PLAYED_ANGLE_RAD, PLAYED_ANGLE_RAD, 145)
    x = x[x != 0.0]
    restoring = -acceleration({k: v for k, v in values.items() if k in RESTORING_TERMS}, x, np.zeros_like(x))
    wrong = np.flatnonzero(restoring * x <= 0)
    if wrong.size:
        return f"the restoring is not positive at {math.degrees(x[wrong[0]]):+.0f} deg (the model capsizes)"
    return _term_too_large(values, RESTORING_TERMS, PLAYED_ANGLE_RAD, 0.0, stiffness)


def _damping_refusal(values: Mapping[str, float], omega: float) -> str | None:
    """Energy leaves at every speed from a settled swing to the largest one, and the decay swings."""
    v = np.geomspace(omega * SETTLED_ANGLE_RAD, omega * PLAYED_ANGLE_RAD, 97)
    damping = -acceleration({k: values[k] for k in DAMPING_TERMS if k in values}, np.zeros_like(v), v)
    wrong = np.flatnonzero(damping <= 0)
    if wrong.size:
        speed = v[wrong[0]]
        return (
            f"not damped at {math.degrees(speed):.3g} deg/s (b1 = {values.get('b1', 0.0):g}: b1 x' + "
            "b2|x'|x' + b3 x'^3 must take energy out at every speed, or the swings grow)"
        )
    ratio = values.get("b1", 0.0) / (2 * omega)
    if ratio >= 1:
        return f"over-damped: b1 / (2 omega0) = {ratio:.3g} (at least 1: the model creeps back, no swing)"
    return _term_too_large(values, DAMPING_TERMS, 0.0, omega * PLAYED_ANGLE_RAD, omega**2)


def _term_too_large(
    values: Mapping[str, float], names: Sequence[str], x: float, v: float, stiffness: float
) -> str | None:
    scale = MAX_TERM_RATIO * stiffness * PLAYED_ANGLE_RAD
    phi = regressors(np.array([x]), np.array([v]), list(names))[0]
    for name, value in zip(names, phi, strict=True):
        if abs(values.get(name, 0.0) * value) > scale:
            return (
                f"{name} = {values[name]:g} is too large: more than {MAX_TERM_RATIO:g} times the linear "
                f"restoring at {math.degrees(PLAYED_ANGLE_RAD):g} deg (the integration would crawl)"
            )
    return None


def integrate_reference(
    rhs: Callable[[float, np.ndarray], Sequence[float]],
    t: np.ndarray,
    state0: Sequence[float],
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_step: float = 0.0,
) -> np.ndarray:
    """The state at each of the increasing times ``t`` (shape (len(t), len(state0))), from ``state0`` at
    ``t[0]``: ODEPACK's LSODA (``scipy.integrate.odeint``), which switches to a stiff method where
    Coulomb friction's steep slope at rest needs one. It is the reference that makes known-truth data,
    independent of the fits' own kernels, and several times faster than scipy's DOP853 at the same
    tolerance. ``max_step`` > 0 bounds its steps (a forcing with short pulses)."""
    from scipy.integrate import odeint  # scipy.integrate costs a second to import: only when simulating

    states, info = odeint(
        rhs, list(state0), t, rtol=rtol, atol=atol, hmax=max_step, tfirst=True, full_output=True
    )
    if info["message"] != "Integration successful.":  # pragma: no cover - only on absurd coefficients
        raise RuntimeError(f"decay simulation failed: {info['message']}")
    return np.asarray(states)


def simulate_decay(
    coefficients: Mapping[str, float],
    t: np.ndarray,
    angle0: float,
    rate0: float = 0.0,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    forcing: Callable[[float], float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate the decay equation from (angle0, rate0) at t[0]; return (angle, rate) at t.

    A reference integrator (adaptive, tight tolerance) for making known-truth data
    and for the simulated sensor; the estimators use their own fast kernels.
    ``forcing(t)`` (rad/s², per unit inertia) makes records that stop being free decays
    (a second push, a carriage stop); steps are then at most one sample long so no pulse is missed.
    """
    t = np.asarray(t, dtype=float)
    damping_and_restoring = terms_sum(coefficients)

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        x, v = float(y[0]), float(y[1])
        return [v, -damping_and_restoring(x, v) + (forcing(_t) if forcing is not None else 0.0)]

    if t.size == 1:
        return np.array([angle0]), np.array([rate0])
    max_step = float(np.min(np.diff(t))) if forcing is not None else 0.0
    states = integrate_reference(rhs, t, [angle0, rate0], rtol=rtol, atol=atol, max_step=max_step)
    return states[:, 0], states[:, 1]
