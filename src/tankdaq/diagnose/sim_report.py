"""A simulation-vs-measurement comparison told four ways: terminal lines, JSON, a Markdown report, rerun.

All read a fitted ``SimulationComparison``; degrees and SI units are made here, at the edge. The
figures and the rerun recording are ``viz.diagnose_view``'s, given the curves (in rad) and the story.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from ..ident.derived import b44_hat_factor, extinction_curve
from ..ident.interval_labels import FIT_95
from ..physics.terms import TERM_TABLE
from ..records import DecayRun
from ..store.safe_write import write_text_new
from ..viz import diagnose_view, plots
from .agreement import DampingPoint
from .compare import CorrectionStep, SimulationComparison
from .components import ComponentScaling
from .correction import Correction, moment_name
from .fitting import RunPrediction
from .report import diagnostics_summary, finite_json, report_folder
from .residuals import SPECTRUM_MEANING
from .simulation import SERIES


def _deg(value_rad: float) -> float:
    return float(np.degrees(value_rad))


def _coefficients_text(coefficients: dict[str, float]) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in coefficients.items())


def damping_sentence(points: list[DampingPoint]) -> str:
    """'simulation damping (B_eq) is 26 % of measured at 1.1 deg (95 %: 25-27 %), 11 % at 10.1 deg'."""
    ends = [points[0], points[-1]] if len(points) > 1 else points
    parts = []
    for i, p in enumerate(ends):
        low, high = p.ratio_ci95
        share = f"{100 * p.ratio:.0f} %" + (" of measured" if i == 0 else "")
        parts.append(f"{share} at {p.amplitude_deg:.1f} deg (95 %: {100 * low:.0f}-{100 * high:.0f} %)")
    verdict = "disagrees" if any(p.disagrees for p in points) else "agrees within the intervals"
    return f"simulation damping (B_eq) is {', '.join(parts)}: {verdict}"


def period_sentence(comparison: SimulationComparison) -> str:
    """'period agrees to 0.1 % (...)' or 'simulation period is 3.1 % longer (...): stiffness disagrees'."""
    check = comparison.period_check_
    if check.cycles == 0:
        return "period: too few measured cycles to compare"
    where = (
        f"(measured {check.measured_s:.4g} s median over {check.cycles} cycles, "
        f"simulation {check.simulation_s:.4g} s at their amplitude; 95 % +-{100 * check.ci95:.2f} %)"
    )
    if not check.disagrees:
        return f"period agrees to {100 * abs(check.error):.1f} % {where}"
    longer = "longer" if check.error > 0 else "shorter"
    return f"simulation period is {100 * abs(check.error):.1f} % {longer} {where}: stiffness disagrees"


def _step_line(step: CorrectionStep, simulated: dict[str, float]) -> str:
    """'added' for a new term; a term of the simulation's own is 'raised' or 'lowered' (an excess)."""
    effect = step.effect
    held = effect.increments if effect.increments in simulated else None
    verb = "added" if held is None else "lowered" if step.added.get(held, 0.0) < 0 else "raised"
    added = ", ".join(
        f"{k} {v:+.4g} {TERM_TABLE[k].unit if k in TERM_TABLE else ''}".rstrip()
        for k, v in step.added.items()
    )
    kept = ",".join(step.fixed) or "none"
    return (
        f"{verb} {effect.name} ({effect.family}; {effect.physics}): {added}, fitted with the simulation's "
        f"{kept} fixed; RMS {_deg(step.rms_before_rad):.3f} -> {_deg(step.rms_after_rad):.3f} deg, "
        f"dBIC {step.delta_bic:.0f}"
    )


def _free_line(comparison: SimulationComparison) -> str:
    sim = comparison.equation_.coefficients
    free = comparison.free_.coefficients
    moved = []
    for k, v in free.items():
        if sim.get(k):
            moved.append(f"{k} {sim[k]:.4g} -> {v:.4g} ({100 * (v / sim[k] - 1):+.0f} %)")
        elif k in TERM_TABLE:
            moved.append(f"{k} {v:.4g}")
    return (
        f"free refit (every term free, for comparison): {'; '.join(moved)}; "
        f"RMS {_deg(comparison.rms_rad_['free refit']):.3f} deg"
    )


def correction_line(fix: Correction, axis: str) -> str:
    """The correction a simulation code takes, in SI at model and full scale when the hull allows."""
    if not fix.terms:
        return "correction for the simulation code: none"
    parts = []
    for term in fix.terms:
        spec = TERM_TABLE[term.term]
        text = f"{spec.description} {term.term} {term.per_unit_inertia:+.4g} {spec.unit}"
        if term.model_scale is not None:
            text += f" = {moment_name(term.term, axis)} {term.model_scale:+.4g} {term.unit} at model scale"
        if term.full_scale is not None:
            text += f", {term.full_scale:+.4g} {term.unit} at full scale"
        parts.append(text)
    inertia = "" if fix.total_inertia_kg_m2 is None else f"; I = {fix.total_inertia_kg_m2:.4g} kg m^2"
    scale = "" if fix.scale_factor is None else f"; Froude scale 1:{fix.scale_factor:g}"
    notes = "; ".join(fix.notes)
    return f"correction for the simulation code: {'; '.join(parts)}{inertia}{scale} ({notes})"


def story(comparison: SimulationComparison) -> list[str]:
    """One line per finding, as a lab engineer would tell it."""
    sim = comparison.simulation
    eq = comparison.equation_
    head = f"simulation {sim.name} ({sim.kind}): {_coefficients_text(eq.coefficients)}"
    if eq.series_rms_rad is not None:
        head += (
            " (its equation, identified by output error: reproduces the series to "
            f"{_deg(eq.series_rms_rad):.2g} deg RMS)"
        )
    lines = [head, *(f"simulation: {note}" for note in sim.notes)]
    lines += [f"matched: {m.line}" for m in comparison.matches_]
    diag = comparison.diagnostics_
    lines += [
        period_sentence(comparison),
        damping_sentence(comparison.damping_),
        "residual of the simulation from the measured release: "
        f"RMS {_deg(comparison.rms_rad_['simulation']):.3f} deg "
        f"(a model fitted to the measurement: {_deg(comparison.rms_rad_['measured model']):.3f} deg); "
        f"{SPECTRUM_MEANING[diag.spectrum.location]}; Ljung-Box p {diag.ljung_box_p:.2g}",
        "disagreement: " + (" and ".join(comparison.disagrees_in_) or "none beyond the intervals"),
    ]
    lines += [_step_line(step, eq.coefficients) for step in comparison.steps_]
    if comparison.steps_:
        lines += [_free_line(comparison), correction_line(comparison.correction_, comparison.runs_[0].axis)]
    lines += [scaling.line for scaling in comparison.scalings_]
    lines += [f"not named: {name} ({why})" for name, why in comparison.withheld_.items()]
    if comparison.differs_ is not None:
        lines.append(f"what differs: {comparison.differs_}")
    lines += [f"to meet the measurement: {line}" for line in comparison.component_changes_]
    lines += [f"warning: {w}" for w in comparison.warnings_]
    lines.append(comparison.verdict_)
    return lines


def _curve_runs(curves: list[RunPrediction]) -> list[DecayRun]:
    return [DecayRun(c.t, c.angle, name=c.name) for c in curves]


def decrements(comparison: SimulationComparison) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Decrement per half cycle against mean amplitude (rad), from the peaks of each curve alike."""
    offsets = comparison.reference_.offsets_
    model = comparison.reference_.coefficients_  # its curve is not used: the points of each curve are
    out = {"measured": extinction_curve(comparison.runs_, offsets, model)}
    for name in ("simulation", "corrected"):
        out[name] = extinction_curve(_curve_runs(comparison.curves_[name]), [0.0] * len(offsets), model)
    return {name: (curve.mean_amplitude, curve.decrement) for name, curve in out.items()}


def b44_hat_per_b_eq(comparison: SimulationComparison) -> float | None:
    """B̂44 per B_eq/I: I √(B/2g) / (ρ∇B²), I the correction's total inertia (Δ g GM / c1), for roll
    where the hull gives its beam and displacement; None otherwise."""
    inertia = comparison.correction_.total_inertia_kg_m2
    if comparison.hull is None or inertia is None or comparison.runs_[0].axis != "roll":
        return None
    factor = b44_hat_factor(comparison.hull)
    return None if factor is None else inertia * factor


def _band(points: list[DampingPoint], side: str, hat: float | None) -> dict[str, Any]:
    values = [getattr(p, side) for p in points]
    band: dict[str, Any] = {
        "b_eq_1_s": [v for v, _ in values],
        "ci95_1_s": [[v - 1.96 * s, v + 1.96 * s] for v, s in values],
    }
    if hat is not None:
        band["b44_hat"] = [v * hat for v, _ in values]
    return band


def _simulation_part(c: SimulationComparison) -> dict[str, Any]:
    eq = c.equation_
    std = np.sqrt(np.clip(np.diag(eq.covariance), 0, None)).tolist()
    return {
        "name": c.simulation.name,
        "kind": c.simulation.kind,
        "notes": list(c.simulation.notes),
        "equation": {
            "terms": list(eq.terms),
            "coefficients": eq.coefficients,
            "std": dict(zip(eq.terms, std, strict=True)),
            "series_rms_deg": None if eq.series_rms_rad is None else _deg(eq.series_rms_rad),
        },
    }


def _period_part(c: SimulationComparison) -> dict[str, Any]:
    check = c.period_check_
    return {
        "points": [{**asdict(p), "simulation_error": p.simulation_error} for p in c.periods_],
        "error": check.error,
        "error_ci95": check.ci95,
        "cycles": check.cycles,
        "agrees": not check.disagrees,
        "cycle_periods_s": c.cycle_periods_s_,
        "sentence": period_sentence(c),
    }


def _damping_part(c: SimulationComparison) -> dict[str, Any]:
    hat = b44_hat_per_b_eq(c)
    return {
        "amplitudes_deg": c.amplitudes_deg_,
        **{side: _band(c.damping_, side, hat) for side in ("measured", "simulation", "corrected")},
        "ratio": [p.ratio for p in c.damping_],
        "ratio_ci95": [list(p.ratio_ci95) for p in c.damping_],
        "disagrees": [p.disagrees for p in c.damping_],
        "sentence": damping_sentence(c.damping_),
    }


def _step_part(s: CorrectionStep) -> dict[str, Any]:
    effect = s.effect
    return {
        "effect": effect.name,
        "key": effect.key,
        "family": effect.family,
        "physics": effect.physics,
        "terms": effect.adds,
        "added": s.added,
        "fixed": s.fixed,
        "delta_bic": s.delta_bic,
        "rms_before_deg": _deg(s.rms_before_rad),
        "rms_after_deg": _deg(s.rms_after_rad),
    }


def _scaling_part(s: ComponentScaling) -> dict[str, Any]:
    """A changed term as a scaling of its components (``diagnose.components``), for the JSON."""
    return {
        "term": s.term,
        "label": s.label,
        "excess": s.excess,
        "times_measured": s.times_measured,
        "predicted": s.predicted,
        "final": s.final,
        "factor": s.factor,
        "members": s.members,
        "factor_alone": s.alone(),
        "amplitude_deg": s.amplitude_deg,
        "b44_model_n_m_s": s.b44_model_n_m_s,
        "b44_full_n_m_s": s.b44_full_n_m_s,
        "notes": s.notes,
        "line": s.line,
    }


def summary(comparison: SimulationComparison) -> dict[str, Any]:
    """The JSON document of ``tankdaq diagnose --simulation ... --json``."""
    c = comparison
    matches = [
        {
            "measured": m.measured,
            "simulated": m.simulated,
            "measured_angle_deg": _deg(m.measured_angle_rad),
            "simulated_angle_deg": _deg(m.simulated_angle_rad),
        }
        for m in c.matches_
    ]
    reference = c.reference_
    return {
        "simulation": _simulation_part(c),
        "matches": matches if c.simulation.kind == SERIES else None,
        "runs": [run.name for run in c.runs_],
        "release_states": [{"angle_deg": _deg(a), "rate_deg_s": _deg(v)} for a, v in c.release_states_],
        "measured_model": {
            "terms": list(reference.terms_),
            "coefficients": reference.coefficients_,
            "std": reference.std_,
        },
        "period": _period_part(c),
        "damping": _damping_part(c),
        "extinction": {
            name: {"mean_amplitude_deg": np.degrees(a).tolist(), "decrement_deg": np.degrees(d).tolist()}
            for name, (a, d) in decrements(c).items()
        },
        "cycle_trend": {
            name: {"zeta_slope_per_rad": t.zeta_slope_per_rad, "zeta_intercept": t.zeta_intercept}
            for name, t in c.trends_.items()
        },
        "residual": {**diagnostics_summary(c.diagnostics_), "ljung_box_p": c.diagnostics_.ljung_box_p},
        "disagrees_in": list(c.disagrees_in_),
        "steps": [_step_part(s) for s in c.steps_],
        "corrected": {"terms": c.corrected_.spec.labels, "coefficients": c.corrected_.coefficients},
        "free_refit": {"coefficients": c.free_.coefficients, "std": c.free_.std},
        "gap": {
            **{f"{name.replace(' ', '_')}_deg": _deg(value) for name, value in c.rms_rad_.items()},
            "reduction": c.gap_reduction_,
        },
        "correction": asdict(c.correction_),
        "component_changes": c.component_changes_,
        "speed_m_s": c.simulation.speed_m_s,
        "scalings": [_scaling_part(scaling) for scaling in c.scalings_],
        "withheld": c.withheld_,
        "evidence": {key: {"seen": e.seen, "line": e.line} for key, e in c.evidence_.items()},
        "differs": c.differs_,
        "warnings": c.warnings_,
        "verdict": c.verdict_,
    }


def summary_json(comparison: SimulationComparison) -> str:
    """``summary`` as one line of valid JSON (no NaN)."""
    return json.dumps(finite_json(summary(comparison)))


def figures(comparison: SimulationComparison) -> dict[str, Any]:
    """The report's figures by file name: the curves side by side, and damping with the extinction curve."""
    c = comparison
    labels = plots.run_labels(c.runs_)
    gap = (_deg(c.rms_rad_["simulation"]), _deg(c.rms_rad_["corrected"]))
    bands = {
        side: (
            np.array([getattr(p, side)[0] for p in c.damping_]),
            np.array([getattr(p, side)[1] for p in c.damping_]),
        )
        for side in ("measured", "simulation", "corrected")
    }
    return {
        "simulation.png": diagnose_view.simulation_figure(
            c.curves_["simulation"], c.curves_["corrected"], labels, gap
        ),
        "damping.png": diagnose_view.damping_figure(
            c.amplitudes_deg_, bands, decrements(c), b44_hat_per_b_eq(c)
        ),
    }


#: The files of a simulation's report: a ``--report`` folder holding one is refused before any fit.
REPORT_FILES = ("simulation.md", "simulation.png", "damping.png")


def write_report(comparison: SimulationComparison, directory: str | Path) -> Path:
    """``directory/simulation.md`` with the story, the gap table and two PNG figures."""
    from ..viz.plots import save_png

    out = report_folder(directory, REPORT_FILES)
    for name, fig in figures(comparison).items():
        save_png(fig, out / name)
    return write_text_new(out / REPORT_FILES[0], "\n".join(_report_lines(comparison)))


def _damping_rows(comparison: SimulationComparison) -> list[str]:
    """The B_eq table: per amplitude each side's B_eq/I ± 95 % and, where the hull allows, its B̂44."""
    hat = b44_hat_per_b_eq(comparison)
    sides = ("measured", "simulation", "corrected")
    head = "| amplitude (deg) | measured | simulation | corrected | simulation / measured |"
    if hat is not None:
        head += " B̂44 measured | B̂44 simulation | B̂44 corrected |"
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for p in comparison.damping_:
        cells = [f"{p.amplitude_deg:.2f}"]
        cells += [f"{getattr(p, side)[0]:.4g} ± {1.96 * getattr(p, side)[1]:.2g}" for side in sides]
        cells.append(f"{100 * p.ratio:.0f} %")
        if hat is not None:
            cells += [f"{getattr(p, side)[0] * hat:.4g}" for side in sides]
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def _report_lines(comparison: SimulationComparison) -> list[str]:
    """simulation.md: the story, the gap table, the B_eq table and the figures."""
    rows = [f"| {name} | {_deg(value):.4f} |" for name, value in comparison.rms_rad_.items()]
    return [
        "# Simulation against measurement",
        "",
        f"Simulation: {comparison.simulation.name}. Runs: {', '.join(r.name for r in comparison.runs_)}",
        "",
        "## Story",
        "",
        *[f"- {line}" for line in story(comparison)],
        "",
        "## The gap (RMS of the angle over the measured decay, every model from the measured release)",
        "",
        "| model | RMS angle (deg) |",
        "|---|---|",
        *rows,
        "",
        f"Gap reduction (1 - corrected / simulation): {100 * comparison.gap_reduction_:.1f} %",
        "",
        f"## B_eq per unit inertia (1/s, {FIT_95})",
        "",
        *_damping_rows(comparison),
        "",
        "![measured, simulation and corrected](simulation.png)",
        "",
        "![damping and extinction curve](damping.png)",
        "",
    ]


def save_rrd(comparison: SimulationComparison, path: str | Path) -> Path:
    """The curves side by side and the story in a new .rrd file (open it with ``rerun path``)."""
    labels = plots.short_labels([run.name for run in comparison.runs_])
    return diagnose_view.save_simulation_rrd(
        path, comparison.curves_["simulation"], comparison.curves_["corrected"], labels, story(comparison)
    )
