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

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from .terms import TERMS


def regressors(angle: np.ndarray, rate: np.ndarray, terms: Sequence[str] = TERMS) -> np.ndarray:
    """The value of each term's function of state, shape (n, len(terms)).

    The equation reads ``x'' = -regressors @ coefficients``.
    """
    x = np.asarray(angle, dtype=float)
    v = np.asarray(rate, dtype=float)
    sx = np.sin(x)
    table = {
        "b1": v,
        "b2": np.abs(v) * v,
        "b3": v**3,
        "c1": x,
        "c2": x**2,
        "c3": x**3,
        "s1": sx,
        "s2": sx**2,
        "s3": sx**3,
    }
    unknown = [name for name in terms if name not in table]
    if unknown:
        raise KeyError(f"unknown decay term(s) {unknown}; known: {', '.join(TERMS)}")
    return np.column_stack([table[name] for name in terms]) if terms else np.zeros((x.size, 0))


def acceleration(coefficients: Mapping[str, float], angle: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """x'' for the given state under the given coefficients (missing terms are zero)."""
    names = [k for k in TERMS if coefficients.get(k, 0.0) != 0.0]
    theta = np.array([coefficients[k] for k in names], dtype=float)
    return -(regressors(angle, rate, names) @ theta) if names else np.zeros(np.shape(angle))


def linear_stiffness(coefficients: Mapping[str, float]) -> float:
    """d(restoring)/dx at x = 0: c1 + s1. Its square root is the undamped natural frequency."""
    return float(coefficients.get("c1", 0.0) + coefficients.get("s1", 0.0))


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
    from scipy.integrate import solve_ivp  # scipy.integrate costs a second to import: only when simulating

    t = np.asarray(t, dtype=float)
    names = [k for k in TERMS if coefficients.get(k, 0.0) != 0.0]
    theta = np.array([coefficients[k] for k in names], dtype=float)

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        acc = -(regressors(np.array([y[0]]), np.array([y[1]]), names)[0] @ theta) if names else 0.0
        return [y[1], float(acc) + (forcing(_t) if forcing is not None else 0.0)]

    if t.size == 1:
        return np.array([angle0]), np.array([rate0])
    max_step = float(np.min(np.diff(t))) if forcing is not None else np.inf
    sol = solve_ivp(
        rhs,
        (t[0], t[-1]),
        [angle0, rate0],
        t_eval=t,
        rtol=rtol,
        atol=atol,
        method="DOP853",
        max_step=max_step,
    )
    if not sol.success:  # pragma: no cover - only on absurd coefficients
        raise RuntimeError(f"decay simulation failed: {sol.message}")
    return sol.y[0], sol.y[1]
