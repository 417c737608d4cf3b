"""A fitted decay's uncertainty budgets: the fit, its decays, the hull and the device put together for
``ident.budget`` (``identify``, ``campaign`` and the session report call ``fit_budgets``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..records import DecayRun
from .budget import Budget, FitUncertainty, budgets
from .budget_inputs import (
    DeviceProfile,
    HullFigures,
    device_profile,
    device_sources,
    hull_sources,
    nominal_inputs,
    reference_amplitudes,
    reported_quantities,
)
from .conditions import condition_of
from .derived import b44_hat_factor, tested_amplitudes_deg
from .equation_error import EquationErrorFit
from .output_error import OutputErrorFit


def hull_figures(hull: Any, axis: str, draft: float, scale_factor: float | None = None) -> HullFigures:
    """The hull's numbers at the draft factor ``draft`` (the displacement scaled with it, as
    ``report.dimensional_summary`` does), with the uncertainties its file gives; none without a hull."""
    if hull is None:
        return HullFigures(scale_factor=scale_factor)
    axis_figures = hull.particulars(axis)
    displacement = None if hull.displacement_kg is None else hull.displacement_kg * draft
    displacement_u = hull.displacement_uncertainty_kg
    hat = b44_hat_factor(hull, draft) if axis == "roll" else None
    return HullFigures(
        gm_m=axis_figures.gm_m,
        gm_u=axis_figures.gm_uncertainty_m,
        displacement_kg=displacement,
        displacement_u=None if displacement_u is None else displacement_u * draft,
        gyradius_m=axis_figures.radius_of_gyration_m,
        gyradius_u=axis_figures.radius_of_gyration_uncertainty_m,
        added_inertia_fraction=hull.main_particulars.at(draft).get("added_inertia_fraction"),
        hat_factor_per_kg=None if hat is None or displacement is None else hat * displacement,
        scale_factor=scale_factor,
    )


def per_decay_coefficients(estimator: Any, runs: Sequence[DecayRun]) -> tuple[dict[str, float], ...]:
    """Each decay fitted alone, for Type A from repeats: an output-error fit warm-started from the joint
    fit's coefficients, an equation-error fit as it is; none for one decay, for the seeds' searches (GA,
    PSO: minutes per fit) or for decays of several conditions (``--joint``), whose budgets use the fit's
    covariance and say so."""
    if len(runs) < 2 or not isinstance(estimator, OutputErrorFit | EquationErrorFit):
        return ()
    if len({condition_of(run) for run in runs}) > 1:  # pooled conditions (--joint) are not repeats
        return ()
    out = []
    for run in runs:
        alone = (
            estimator.clone(compute_diagnostics=False)
            if isinstance(estimator, OutputErrorFit)
            else estimator.clone()
        )
        if isinstance(alone, OutputErrorFit):
            alone.fit([run], start=dict(estimator.coefficients_))
        else:
            alone.fit([run])
        out.append(dict(alone.coefficients_))
    return tuple(out)


def initial_amplitude_deg(runs: Sequence[DecayRun], offsets: Sequence[float]) -> float:
    """The decays' mean initial amplitude (deg): where the device's accuracy sets the angle's scale."""
    return float(
        np.mean([math.degrees(np.max(np.abs(r.angle - o))) for r, o in zip(runs, offsets, strict=True)])
    )


def fit_budgets(
    estimator: Any,
    runs: Sequence[DecayRun],
    tested_deg: Sequence[float],
    hull: HullFigures | None = None,
    device: DeviceProfile | None = None,
    per_decay: Sequence[dict[str, float]] | None = None,
) -> list[Budget]:
    """The budget of every reported quantity of a fitted ``estimator`` of ``runs``.

    ``tested_deg``: the amplitudes the decays cover (the budgets are stated at the multiples of 5 deg
    among them); ``device``: the device profile (default: from the decays' product code, else the
    MTi-G-710's); ``per_decay``: each decay's own coefficients (default: fitted here).
    """
    from .report import covariance_of

    hull = hull or HullFigures()
    profile = device or device_profile(str(runs[0].meta.get("product_code", "")))
    decays = tuple(per_decay_coefficients(estimator, runs) if per_decay is None else per_decay)
    fit = FitUncertainty(
        {k: estimator.coefficients_[k] for k in estimator.terms_},
        covariance_of(estimator),
        str(getattr(estimator, "cov_type", "classic")),
        tuple(dict(c) for c in decays),
        len(runs),
    )
    duration = float(np.mean([run.t[-1] - run.t[0] for run in runs]))
    sources = device_sources(profile, initial_amplitude_deg(runs, estimator.offsets_), duration)
    sources += hull_sources(hull)
    quantities = reported_quantities(estimator.terms_, runs[0].axis, reference_amplitudes(tested_deg), hull)
    return budgets(quantities, fit, nominal_inputs(hull), sources)


def group_budgets(fit: Any, runs: Sequence[DecayRun], hull: Any, draft: float) -> tuple[dict[str, Any], ...]:
    """A campaign group's budgets (``Budget.as_dict``): Type A from its repeats (each decay refitted
    alone), its hull's uncertainties; none for a group not fitted."""
    if fit is None:
        return ()
    tested = tested_amplitudes_deg(runs, fit.offsets_)
    figures = hull_figures(hull, runs[0].axis, draft)
    return tuple(b.as_dict() for b in fit_budgets(fit, runs, tested, figures))
