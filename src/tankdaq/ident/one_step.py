"""The seeds' one-step-ahead rate error: the objective GA/PSO minimise, reported for every fit.

Apart from the output-error engine so the seed methods and reports can score a coefficient set
without fitting anything.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..records import DecayRun
from .compiled import term_codes, term_matrix


def seed_objective(
    terms: Sequence[str],
    theta: np.ndarray,
    runs: Sequence[DecayRun],
    offsets: Sequence[float],
    inputs: Sequence[np.ndarray] | None = None,
    friction_eps: float = 1e-3,
) -> float:
    """RMS of the one-step-ahead predicted rate (seed 000 eq. 4.5-4.6), rad/s.

    As in the seeds' software (and ``ident.evolutionary``): one Euler step from
    the measured state at k predicts the rate at k+1; the measured rate is the
    gyro, or the angle differentiated when there is none. The angle is taken
    relative to the fitted offset, the model's equilibrium.
    """
    return one_step_rms(
        term_codes(terms), np.asarray(theta, dtype=float), runs, offsets, inputs, friction_eps
    )


def one_step_rms(
    codes: np.ndarray,
    theta: np.ndarray,
    runs: Sequence[DecayRun],
    offsets: Sequence[float],
    inputs: Sequence[np.ndarray] | None,
    friction_eps: float,
) -> float:
    """``seed_objective`` on term codes already compiled (the estimator keeps them)."""
    errors = []
    for r, (run, offset) in enumerate(zip(runs, offsets, strict=True)):
        x = run.angle - offset
        v = run.rate if run.rate is not None else np.gradient(run.angle, run.t)
        u = np.zeros_like(run.t) if inputs is None else inputs[r]
        acc = -term_matrix(codes, x[:-1], v[:-1], u[:-1], friction_eps) @ theta
        errors.append(v[1:] - (v[:-1] + np.diff(run.t) * acc))
    return rms(np.concatenate(errors))


def rms(a: np.ndarray) -> float:
    """Root mean square."""
    return float(np.sqrt(np.mean(np.square(a))))
