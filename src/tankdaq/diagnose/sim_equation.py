"""The equation of a decay series found by fitting: a lab's simulated series (``identify_series``) and the
measured side (``best_damping_form``) get the same treatment, cubic restoring with the better damping shape.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import BadIdentificationInput
from ..ident.derived import b_eq, equivalent_frequency
from ..ident.output_error import OutputErrorFit
from ..records import DecayRun
from .workflow import initial_guess

#: The measured side's models: cubic restoring with quadratic or with cubic damping (ITTC eq. 6 + 9), HAC
#: intervals; the better BIC is taken. A model with the other damping shape bends its B_eq at the ends of
#: the amplitude band and its restoring; one with both is over-parameterised on one decay (b2 < 0).
REFERENCE_MODELS = (("b1", "b2", "c1", "c3"), ("b1", "b3", "c1", "c3"))
#: Dropped when it adds less than this to B_eq (damping) or to the stiffness (restoring) at the top amplitude.
NEGLIGIBLE_DAMPING, NEGLIGIBLE_RESTORING = 0.01, 0.001


@dataclass
class SimEquation:
    """The simulation's own equation per unit inertia, with its covariance (zeros when given exactly)."""

    terms: tuple[str, ...]
    coefficients: dict[str, float]
    covariance: np.ndarray
    series_rms_rad: float | None  # how well it reproduces the simulated series (None: a model)


def best_damping_form(runs: Sequence[DecayRun], starts: int = 1) -> OutputErrorFit:
    """The better (BIC) of ``REFERENCE_MODELS`` fitted by output error to ``runs``. With ``starts=2`` each
    is also started from the spectrum's frequency and the peaks' decrement (``workflow.initial_guess``):
    over tens of lightly damped cycles either start alone can end in a wrong minimum (a simulated series;
    seen both ways), the better of the two does not."""
    fits = []
    for terms in REFERENCE_MODELS:
        for guess in (None, initial_guess(runs, terms))[:starts]:
            try:
                fits.append(OutputErrorFit(terms, compute_diagnostics=False).fit(runs, start=guess))
            except BadIdentificationInput:
                continue  # diverged from this start: the other one counts
    if not fits:
        raise BadIdentificationInput("no decay model fits these runs (every fit diverged)")
    return min(fits, key=lambda fit: fit.bic_)


def identify_series(runs: Sequence[DecayRun]) -> SimEquation:
    """The simulated decays' equation: the better damping form (``best_damping_form``), then the terms
    that change neither B_eq nor the stiffness noticeably at the largest amplitude dropped."""
    fit = best_damping_form(runs, starts=2)
    top = max(float(np.max(np.abs(run.angle))) for run in runs)
    terms = fit.terms_
    kept = tuple(t for t in terms if t in ("b1", "c1") or _matters(fit.coefficients_, t, top))
    if kept != terms:
        fit = OutputErrorFit(kept, compute_diagnostics=False).fit(runs, start=fit.coefficients_)
    residual = np.concatenate([res["angle"] for res in fit.residuals_])
    return SimEquation(kept, dict(fit.coefficients_), fit.covariance_, float(np.sqrt(np.mean(residual**2))))


def _matters(coefficients: dict[str, float], term: str, amplitude: float) -> bool:
    """Whether a term changes B_eq or the stiffness noticeably at the largest amplitude."""
    alone = {"b1": 0.0, "c1": coefficients["c1"], term: coefficients[term]}
    if term.startswith("b"):
        return abs(b_eq(alone, amplitude)) > NEGLIGIBLE_DAMPING * abs(b_eq(coefficients, amplitude))
    omega2 = equivalent_frequency(alone, amplitude) ** 2
    return abs(omega2 / coefficients["c1"] - 1.0) > NEGLIGIBLE_RESTORING
