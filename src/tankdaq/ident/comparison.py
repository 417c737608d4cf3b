"""Fits made to compare and to report: every model on the same runs (``tankdaq identify --compare``),
the leave-one-run-out error, and a fit checked against a known truth (the demo's hull).

The summaries and text they show are ``ident.report``'s; the fitting is here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..physics.models import MODEL_ALIASES, resolve_model
from ..records import DecayRun
from .estimators import make_estimator
from .output_error import OutputErrorFit
from .report import summarize


def group_models(models: Sequence[str]) -> dict[tuple[str, ...], list[str]]:
    """Model names (aliases or term lists) grouped by their term set, in first-seen order."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for name in models:
        groups.setdefault(resolve_model(name), []).append(name)
    return groups


def compare_models(
    runs: Sequence[DecayRun],
    models: Sequence[str] = tuple(MODEL_ALIASES),
    method: str = "oe",
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Fit every model; rows with seed objective, R^2, BIC and (several runs) leave-one-run-out error.

    Aliases with identical term sets are fitted once and listed together. The
    held-out error is the angle RMS (deg) on each left-out run with the
    coefficients fitted on the others and only its initial state and offset free.
    """
    rows = []
    for terms, names in group_models(models).items():
        if progress is not None:
            progress(names[0])
        estimator = make_estimator(method, terms).fit(runs)
        summary = summarize(estimator, runs, method)
        rows.append(
            {
                "models": names,
                "terms": list(terms),
                "n_terms": len(terms),
                "seed_objective": summary.seed_objective,
                "r2_angle": summary.r2_angle,
                "bic": summary.bic,
                "held_out_rms_deg": held_out_rms_deg(terms, runs) if len(runs) > 1 else None,
            }
        )
    return sorted(rows, key=lambda row: row["bic"] if row["bic"] is not None else -row["r2_angle"])


def held_out_rms_deg(terms: Sequence[str], runs: Sequence[DecayRun]) -> float:
    """Leave-one-run-out angle RMS (deg): coefficients from the other runs, the left-out run's state free."""
    squares, count = 0.0, 0
    for i, run in enumerate(runs):
        others = [r for j, r in enumerate(runs) if j != i]
        coefficients = OutputErrorFit(terms, compute_diagnostics=False).fit(others).coefficients_
        held = OutputErrorFit(terms, compute_diagnostics=False).fit([run], fixed_coefficients=coefficients)
        squares += float(np.sum(held.residuals_[0]["angle"] ** 2))
        count += run.t.size
    return math.degrees(math.sqrt(squares / count))


def compare_text(rows: list[dict[str, Any]]) -> str:
    """The model-selection table, best (lowest BIC) first."""
    lines = [f"  {'model':<42}{'k':>3}{'seed obj':>11}{'R^2 angle':>11}{'BIC':>13}{'held-out deg':>14}"]
    for row in rows:
        held = f"{row['held_out_rms_deg']:.4f}" if row["held_out_rms_deg"] is not None else "-"
        bic = f"{row['bic']:.1f}" if row["bic"] is not None else "-"
        lines.append(
            f"  {' = '.join(row['models']):<42}{row['n_terms']:>3}{row['seed_objective']:>11.4g}"
            f"{row['r2_angle']:>11.6f}{bic:>13}{held:>14}"
        )
    return "\n".join(lines)


@dataclass
class TruthCheck:
    """One identified coefficient against a known truth (a simulated hull's)."""

    term: str
    value: float
    truth: float
    ci95: tuple[float, float]

    @property
    def inside(self) -> bool:
        """Whether the truth lies inside the 95 % interval."""
        return self.ci95[0] <= self.truth <= self.ci95[1]


def truth_checks(estimator: Any, truth: Mapping[str, float]) -> list[TruthCheck]:
    """Each fitted coefficient against ``truth`` (a term absent from it is 0); none without a truth."""
    if not truth:
        return []
    return [
        TruthCheck(term, value, truth.get(term, 0.0), estimator.ci95_[term])
        for term, value in estimator.coefficients_.items()
    ]
