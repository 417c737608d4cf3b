"""A fitted decay as people read it: one JSON-ready summary and a text report.

Works for any estimator from ``ident.estimators`` (output error, equation
error, the seeds' searches): what an estimator does not provide itself (angle
R^2, seed objective) is computed here from its coefficients, initial states and
offsets, so every method is scored the same way.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..physics.models import model_name
from ..physics.terms import TERM_TABLE, equation_text
from ..records import DecayRun, partial_end
from ..store.csv_import import source_facts
from .budget import text_table
from .compiled import simulate, substeps, term_codes
from .derived import (
    amplitude_table,
    b44_hat_factor,
    damping_ratio,
    dimensional,
    extinction_curve,
    natural_period,
    tested_amplitudes_deg,
)
from .interval_labels import Coverage, IntervalLabel, kind_of
from .intervals import IntervalSummary
from .one_step import seed_objective
from .output_error import OutputErrorFit
from .plausibility import check_runs
from .summary import BertinRow, Coefficient, DampingRow, FitSummary, ModelTerms


def predicted_angles(estimator: Any, runs: Sequence[DecayRun]) -> list[np.ndarray]:
    """Each run's angle as the fitted model simulates it from the fitted initial state and offset."""
    if isinstance(estimator, OutputErrorFit):
        return [estimator.predict(run, run_index=r)[0] for r, run in enumerate(runs)]
    terms = estimator.terms_
    theta = np.array([estimator.coefficients_[k] for k in terms])
    out = []
    for run, (angle0, rate0), offset in zip(runs, estimator.initial_states_, estimator.offsets_, strict=True):
        n_sub = substeps(float(np.max(np.diff(run.t))), theta, terms, float(np.ptp(run.angle)))
        x, _ = simulate(run.t, angle0, rate0, theta, term_codes(terms), np.zeros_like(run.t), 1e-3, n_sub)
        out.append(x + offset)
    return out


def _r2(measured: np.ndarray, predicted: np.ndarray) -> float:
    return float(1.0 - np.sum((measured - predicted) ** 2) / np.sum((measured - measured.mean()) ** 2))


def covariance_of(estimator: Any, std: Mapping[str, float] | None = None) -> np.ndarray:
    """The coefficient covariance, or a diagonal one from ``std`` (default ``std_``) for estimators that
    give only that."""
    cov = getattr(estimator, "covariance_", None)
    if cov is not None:
        return cov
    std = estimator.std_ if std is None else std
    return np.diag([std.get(k, 0.0) ** 2 for k in estimator.terms_])


def partial_decays(runs: Sequence[DecayRun]) -> list[str]:
    """One warning per decay its recording holds only part of (stopped, the device gone, cut: its
    ``meta["ended"]`` is not whole): a fit of it stands for less than the decay."""
    return [
        f"{run.name}: {said}; the fit covers only what was recorded"
        for run in runs
        if (said := partial_end(run)) is not None
    ]


def summarize(
    estimator: Any,
    runs: Sequence[DecayRun],
    method: str = "oe",
    hull: Any = None,
    draft: float = 1.0,
    intervals: IntervalSummary | None = None,
) -> FitSummary:
    """What ``tankdaq identify --json`` prints (``FitSummary.to_dict``; angles in deg at this edge).

    ``intervals`` (a bootstrap or the repeats' spread) replace the fit's own std and 95 % interval.
    """
    terms = estimator.terms_
    coefficients = dict(estimator.coefficients_)
    std, ci95 = (intervals.std, intervals.ci95) if intervals else (estimator.std_, estimator.ci95_)
    predicted = predicted_angles(estimator, runs)
    all_measured = np.concatenate([run.angle for run in runs])
    all_predicted = np.concatenate(predicted)
    rms = math.sqrt(float(np.mean((all_measured - all_predicted) ** 2)))
    theta = np.array([coefficients[k] for k in terms])
    seed_obj = getattr(estimator, "seed_objective_", None)
    if seed_obj is None:
        seed_obj = seed_objective(terms, theta, runs, estimator.offsets_)
    amplitudes = tested_amplitudes_deg(runs, estimator.offsets_)
    table = amplitude_table(coefficients, covariance_of(estimator, std), amplitudes)
    extinction = extinction_curve(runs, estimator.offsets_, coefficients)
    particulars = hull.particulars(runs[0].axis) if hull is not None else None
    findings = check_runs(
        coefficients, runs, estimator.offsets_, particulars, getattr(hull, "name", "the hull")
    )
    described = intervals.description if intervals else getattr(estimator, "cov_type", "classic")
    dimensions = None if hull is None else dimensional_summary(coefficients, hull, runs[0].axis, draft)
    b44_hat = b44_hat_of(dimensions, hull, runs[0].axis, draft)
    return FitSummary(
        model=ModelTerms(model_name(terms), tuple(terms)),
        method=method,
        axis=runs[0].axis,
        coefficients={
            k: Coefficient(coefficients[k], std[k], (ci95[k][0], ci95[k][1]), TERM_TABLE[k].unit)
            for k in terms
        },
        intervals=described,
        interval_labels={"std": labels_of(described)[0].text, "ci95": labels_of(described)[1].text},
        offset_deg=tuple(math.degrees(o) for o in estimator.offsets_),
        natural_period_s=natural_period(coefficients),
        damping_ratio=damping_ratio(coefficients),
        seed_objective=seed_obj,
        r2_angle=_r2(all_measured, all_predicted),
        nrmse=rms / float(np.ptp(all_measured)),
        bic=getattr(estimator, "bic_", None),
        runs=tuple(
            {
                "file": str(run.meta.get("file", run.name)),
                "name": run.name,
                "samples": int(run.t.size),
                "initial_angle_deg": math.degrees(float(run.angle[0] - offset)),
                "offset_deg": math.degrees(offset),
                "r2_angle": _r2(run.angle, pred),
                "cut": run.meta.get("cut"),
                **({"source": facts} if (facts := source_facts(run.meta)) else {}),
            }
            for run, pred, offset in zip(runs, predicted, estimator.offsets_, strict=True)
        ),
        b_eq=tuple(DampingRow(p.amplitude_deg, p.b_eq, p.b_eq_std, b44_hat(p.b_eq)) for p in table),
        bertin_n=tuple(BertinRow(p.amplitude_deg, p.bertin_n_per_deg, p.bertin_n_std) for p in table),
        extinction={
            "mean_amplitude_deg": np.degrees(extinction.mean_amplitude).tolist(),
            "decrement_deg": np.degrees(extinction.decrement).tolist(),
        },
        plausibility=tuple(finding.as_dict() for finding in findings),
        warnings=(
            *partial_decays(runs),
            *(f.message for f in findings),
            *getattr(estimator, "warnings_", []),
        ),
        elapsed_s=float(getattr(estimator, "elapsed_s_", math.nan)),
        dimensional=dimensions,
    )


def labels_of(intervals: str) -> tuple[IntervalLabel, IntervalLabel]:
    """The labels of an identify summary's ``std`` and ``ci95`` (every ``std`` in it, B_eq's and N's too)
    from how its intervals were found."""
    kind = kind_of(intervals)
    return IntervalLabel(Coverage.ONE_SIGMA, kind), IntervalLabel(Coverage.P95, kind)


def b44_hat_of(
    dimensions: Mapping[str, Any] | None, hull: Any, axis: str, draft: float
) -> Callable[[float], float | None]:
    """B̂44 = B_eq/I · I · √(B/2g) / (ρ∇B²) from B_eq/I, for a roll summary whose hull gives the inertia
    (displacement, GM) and the beam; None otherwise (the rows say B_eq/I only)."""
    inertia = (dimensions or {}).get("total_inertia_kg_m2")
    factor = b44_hat_factor(hull, draft) if axis == "roll" and inertia is not None else None
    if inertia is None or factor is None:
        return lambda b_eq_per_s: None
    return lambda b_eq_per_s: b_eq_per_s * inertia * factor


def dimensional_summary(coefficients: dict[str, float], hull: Any, axis: str, draft: float) -> dict[str, Any]:
    """Dimensional coefficients from the hull's displacement and GM (GM_L for pitch).

    The displacement is scaled with the draft factor (wall-sided approximation):
    the configs give it at the design draft only.
    """
    gm_m = hull.particulars(axis).gm_m
    if hull.displacement_kg is None or gm_m is None:
        return {"note": f"hull {hull.name!r} lacks displacement_kg or the {axis} gm_m"}
    displacement = hull.displacement_kg * draft
    dry = hull.dry_inertia_kg_m2(axis)
    result = dimensional(coefficients, displacement, gm_m, None if dry is None else dry * draft)
    return {
        "hull": hull.name,
        "draft_factor": draft,
        "displacement_kg": displacement,
        "gm_m": gm_m,
        "total_inertia_kg_m2": result.total_inertia_kg_m2,
        "coefficients_si": result.coefficients,
        "added_inertia_fraction": result.added_inertia_fraction,
        "note": "displacement scaled with the draft factor (wall-sided approximation); I = Delta g GM / c1",
    }


def text_report(summary: FitSummary) -> str:
    """A readable report of ``summarize``'s output."""
    angle_name = "phi" if summary.axis == "roll" else "theta"
    hat_head = f"{'B̂44':>11}" if any(row.b44_hat is not None for row in summary.b_eq) else ""
    lines = [
        f"model {summary.model.name} ({', '.join(summary.model.terms)}), "
        f"method {summary.method}, "
        f"{len(summary.runs)} run(s), {summary.axis}",
        "",
        "  " + equation_text(summary.values, angle_name),
        "",
        f"  {'term':<5}{'value':>13}{'std':>12}{'95 % interval':>28}  unit",
    ]
    for k, c in summary.coefficients.items():
        lo, hi = c.ci95
        lines.append(f"  {k:<5}{c.value:>13.6g}{c.std:>12.3g}   [{lo:>11.5g}, {hi:>11.5g}]  {c.unit}")
    lines += [
        "  (std {}, interval {}: {})".format(*labels_of(summary.intervals), summary.intervals),
        "",
        f"  natural period {summary.natural_period_s:.4f} s, damping ratio {summary.damping_ratio:.4f}",
        f"  angle R^2 {summary.r2_angle:.5f}, NRMSE {summary.nrmse:.4f}, "
        f"seed objective {summary.seed_objective:.4g} rad/s",
        "",
        f"  {'amplitude':>10}{'B_eq/I (1/s)':>16}{'std':>11}{hat_head}{'Bertin N (1/deg)':>19}",
    ]
    for b, n in zip(summary.b_eq, summary.bertin_n, strict=True):
        hat = f"{b.b44_hat:>11.4g}" if b.b44_hat is not None else ""
        lines.append(
            f"  {b.amplitude_deg:>8.2f} deg{b.value_per_s:>14.5g}{b.std:>11.2g}{hat}{n.value_per_deg:>19.4g}"
        )
    if hat_head:
        lines.append(
            "  B̂44 = B44 / (ρ ∇ B²) · √(B/2g), B44 = B_eq/I · I (non-dimensional; unchanged at full scale)"
        )
    lines.append("")
    for run in summary.runs:
        lines.append(
            f"  run {run['name']}: start {run['initial_angle_deg']:+.2f} deg, "
            f"offset {run['offset_deg']:+.4f} deg, "
            f"R^2 {run['r2_angle']:.5f}, {run['samples']} samples"
        )
        if run.get("cut"):
            lines.append(f"    cut: {run['cut']['line']}")
    dim = summary.dimensional or {}
    if "total_inertia_kg_m2" in dim:
        lines.append(f"  total inertia {dim['total_inertia_kg_m2']:.4g} kg m^2 ({dim['note']})")
        lines.append("  " + ", ".join(f"{k.upper()} = {v:.4g}" for k, v in dim["coefficients_si"].items()))
    if summary.budget:
        lines += ["", *text_table(summary.budget)]
    for warning in summary.warnings:
        lines.append(f"  warning: {warning}")
    return "\n".join(lines)
