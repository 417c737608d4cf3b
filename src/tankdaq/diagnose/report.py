"""The story of a diagnosis, told four ways: terminal lines, JSON, a Markdown report with PNGs, rerun.

All of them read a fitted ``Diagnoser``; angles are converted to degrees here (the figures and the
rerun recording are drawn by ``viz.diagnose_view`` from the fits' runs, in rad).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..config.validation import refuse_existing
from ..errors import RecordingError
from ..ident.free_decay import cut_lines
from ..ident.plausibility import check_runs
from ..store.safe_write import write_text_new
from ..viz import diagnose_view, plots
from .effects import EffectKind
from .fitting import Fit
from .residuals import SPECTRUM_MEANING, residual_spectrum
from .workflow import Diagnoser, Diagnostics, Step, signature_seen


def _deg(value_rad: float) -> float:
    return float(np.degrees(value_rad))


def _whiteness(p: float) -> str:
    return "white" if p > 0.01 else "not white"


def _fit_summary(fit: Fit) -> dict[str, Any]:
    return {
        "terms": fit.spec.labels,
        "model": fit.spec.describe(),
        "coefficients": fit.coefficients,
        "offsets_rad": fit.offsets,
        "rms_angle_deg": _deg(fit.rms_angle),
        "rms_rate_deg_s": None if fit.rms_rate is None else _deg(fit.rms_rate),
        "nrmse": fit.nrmse_angle,
        "nrmse_rate": fit.nrmse_rate,
        "fit_percent": fit.fit_percent,
        "ljung_box_p": fit.ljung_box_p,
        "rms_noise_units": fit.rms_noise_units,
        "bic": fit.bic,
    }


def diagnostics_summary(diag: Diagnostics) -> dict[str, Any]:
    return {
        "noise_angle_deg": _deg(diag.noise_angle_rad),
        "residual_mean_angle_deg": _deg(diag.residual_mean_angle_rad),
        "residual_mean_rate_deg_s": None
        if diag.residual_mean_rate_rad_s is None
        else _deg(diag.residual_mean_rate_rad_s),
        "spectrum_peak_rad_s": diag.spectrum.peak_rad_s,
        "spectrum_peak_location": diag.spectrum.location,
        "spectrum_meaning": SPECTRUM_MEANING[diag.spectrum.location],
        "corr_with_rate": diag.corr_with_rate,
        "corr_with_angle": diag.corr_with_angle,
        "channel_corr": diag.channel_corr,
        "late_onset_s": [o.onset_s for o in diag.late],
        "late_ratio": [o.ratio for o in diag.late],
    }


def _step_summary(step: Step, diagnoser: Diagnoser) -> dict[str, Any]:
    return {
        "effect": step.effect.name,
        "key": step.effect.key,
        "family": step.effect.family,
        "kind": step.effect.kind,
        "terms": step.effect.adds,
        "delta_bic": step.delta_bic,
        "rms_before_deg": _deg(step.before.rms_angle),
        "rms_after_deg": _deg(step.after.rms_angle),
        "nrmse_after": step.after.nrmse_angle,
        "rms_rate_after_deg_s": None if step.after.rms_rate is None else _deg(step.after.rms_rate),
        "nrmse_rate_after": step.after.nrmse_rate,
        "fit_percent_after": step.after.fit_percent,
        "ljung_box_p_after": step.after.ljung_box_p,
        "coefficients": step.added,
        "std": {k: step.after.std.get(k) for k in step.added},
        "family_evidence": [
            {"effect": f.effect, "delta_bic": f.delta_bic, "bic_vs_chosen": f.vs_chosen} for f in step.family
        ],
        "cut_s": step.cut_s,
        "held_out_rms_noise_units": None if step.held_out is None else list(step.held_out),
        "signature": step.effect.signature,
        "signature_seen": signature_seen(step.effect, step.diagnostics, diagnoser.cycle_trend_),
        "diagnostics_before": diagnostics_summary(step.diagnostics),
    }


def summary(diagnoser: Diagnoser) -> dict[str, Any]:
    """The JSON document of ``tankdaq diagnose --json``."""
    base, final = diagnoser.baseline_, diagnoser.final_
    trend = diagnoser.cycle_trend_
    return {
        "runs": [p.name for p in base.runs],
        "cuts": [run.meta.get("cut") for run in diagnoser.runs_],
        "baseline": {**_fit_summary(base), "diagnostics": diagnostics_summary(diagnoser.diagnostics_[0])},
        "cycle_trend": {
            "zeta_slope_per_rad": trend.zeta_slope_per_rad,
            "zeta_intercept": trend.zeta_intercept,
            "period_slope_s_per_rad2": trend.period_slope_s_per_rad2,
            "damping_grows_with_amplitude": trend.damping_grows_with_amplitude,
            "damping_falls_with_amplitude": trend.damping_falls_with_amplitude,
            "period_changes_with_amplitude": trend.period_changes_with_amplitude,
        },
        "steps": [_step_summary(s, diagnoser) for s in diagnoser.steps_],
        "final": {**_fit_summary(final), "std": final.std},
        "gap_reduction": diagnoser.gap_reduction_,
        "gap_reduction_all_outputs": 1.0 - final.rms_noise_units / base.rms_noise_units,
        "verdict": diagnoser.verdict_,
        "warnings": implausible(diagnoser),
    }


def implausible(diagnoser: Diagnoser) -> list[str]:
    """The final fit's implausibilities (``ident.plausibility``): in the JSON, the story and the report."""
    final = diagnoser.final_
    found = check_runs(final.coefficients, final.estimator.runs_, final.offsets or None)
    return [finding.message for finding in found]


def finite_json(value: Any) -> Any:
    """JSON has no NaN: undefined numbers (a std of a degenerate fit) become null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_json(v) for v in value]
    return value


def summary_json(diagnoser: Diagnoser) -> str:
    """``summary`` as one line of valid JSON."""
    return json.dumps(finite_json(summary(diagnoser)))


def _step_line(step: Step, diagnoser: Diagnoser) -> str:
    effect = step.effect
    after = step.after
    if effect.kind == EffectKind.TRUNCATION:
        cuts = ", ".join(f"{c:.1f}" for c in step.cut_s)
        action = f"cut the records at {cuts} s ({effect.name}, {effect.family})"
    else:
        coeffs = ", ".join(f"{k} = {v:.4g}" for k, v in step.added.items())
        action = f"added {effect.name} ({effect.family}): {coeffs}, dBIC {step.delta_bic:.0f}"
    line = (
        f"{action}; RMS {_deg(after.rms_angle):.3f} deg, fit {after.fit_percent:.1f} %, "
        f"residual {_whiteness(after.ljung_box_p)} (Ljung-Box p {after.ljung_box_p:.2g})"
    )
    if step.held_out is not None:
        line += f"; held-out RMS {step.held_out[0]:.2f} -> {step.held_out[1]:.2f} x noise"
    if step.family:
        rivals = ", ".join(f"{f.effect} worse by {f.vs_chosen:.0f}" for f in step.family)
        line += f"; within the family: {rivals}"
    seen = signature_seen(step.effect, step.diagnostics, diagnoser.cycle_trend_)
    return line + (f" [seen: {'; '.join(seen)}]" if seen else " [signature not evident before the refit]")


def story(diagnoser: Diagnoser) -> list[str]:
    """One line per step, as a lab engineer would tell it."""
    base = diagnoser.baseline_
    diag = diagnoser.diagnostics_[0]
    lines = [
        f"baseline {base.spec.describe()}: RMS {_deg(base.rms_angle):.3f} deg "
        f"(noise {_deg(diag.noise_angle_rad):.3f} deg), fit {base.fit_percent:.1f} %, "
        f"residual {_whiteness(base.ljung_box_p)} (Ljung-Box p {base.ljung_box_p:.2g}); "
        f"{SPECTRUM_MEANING[diag.spectrum.location]}"
    ]
    trend = diagnoser.cycle_trend_
    hints = []
    if trend.damping_grows_with_amplitude:
        hints.append("damping ratio grows with amplitude")
    elif trend.damping_falls_with_amplitude:
        hints.append("damping ratio falls with amplitude")
    if trend.period_changes_with_amplitude:
        hints.append("period changes with amplitude")
    if hints:
        lines.append("cycle by cycle: " + "; ".join(hints))
    lines += [_step_line(s, diagnoser) for s in diagnoser.steps_]
    lines.append(diagnoser.verdict_)
    lines += [f"warning: {line}" for line in implausible(diagnoser)]
    return [f"cut: {line}" for line in cut_lines(diagnoser.runs_)] + lines


def natural_frequency_rad_s(fit: Fit) -> float:
    """The final model's undamped natural frequency (0 when its restoring terms give none)."""
    return float(np.sqrt(max(fit.coefficients.get("c1", 0) + fit.coefficients.get("s1", 0), 0)))


def _gap_cells(fit: Fit) -> str:
    rate = "n/a | n/a" if fit.rms_rate is None else f"{_deg(fit.rms_rate):.4f} | {fit.nrmse_rate:.4f}"
    return (
        f"{_deg(fit.rms_angle):.4f} | {fit.nrmse_angle:.4f} | {rate} | {fit.fit_percent:.2f} "
        f"| {fit.ljung_box_p:.3g}"
    )


#: The files of a diagnosis report: a ``--report`` folder holding one is refused before any fit.
REPORT_FILES = ("diagnose.md", "models.png", "residuals.png", "spectrum.png")


def report_folder(directory: str | Path, names: tuple[str, ...]) -> Path:
    """The report's folder, made where missing (one line when it cannot be), none of whose ``names``
    exists (``store.safe_write``: a report never writes over a file)."""
    out = Path(directory)
    refuse_existing([out / name for name in names])
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordingError(f"cannot create report folder {out}: {exc.strerror or exc}") from None
    return out


#: Zero padding of the report's residual spectrum: a readable curve between the Welch segments' bins.
SPECTRUM_PADDING = 8


def figures(diagnoser: Diagnoser) -> dict[str, Any]:
    """The report's figures by file name: per run (its condition and run number) the models and the
    residuals against the time since release, and the residual spectrum in Hz."""
    base_runs, final_runs = diagnoser.baseline_.runs, diagnoser.final_.runs
    labels = plots.run_labels(diagnoser.runs_)
    omega0 = natural_frequency_rad_s(diagnoser.final_)
    rate_hz = diagnoser.runs_[0].sample_rate
    first, last = (
        residual_spectrum([p.residual_angle for p in fit.runs], rate_hz, omega0, SPECTRUM_PADDING)
        for fit in (diagnoser.baseline_, diagnoser.final_)
    )
    return {
        "models.png": diagnose_view.models_figure(base_runs, final_runs, labels),
        "residuals.png": diagnose_view.residuals_figure(base_runs, final_runs, labels),
        "spectrum.png": diagnose_view.spectrum_figure(first, last, omega0),
    }


def write_report(diagnoser: Diagnoser, directory: str | Path) -> Path:
    """``directory/diagnose.md`` with the story, a step table and three PNG figures."""
    from ..viz.plots import save_png

    out = report_folder(directory, REPORT_FILES)
    for name, fig in figures(diagnoser).items():
        save_png(fig, out / name)
    base = diagnoser.baseline_
    rows = [
        "| step | effect | family | dBIC | RMS angle (deg) | NRMSE angle | RMS rate (deg/s) | NRMSE rate "
        "| fit % | Ljung-Box p |",
        "|---|---|---|---|---|---|---|---|---|---|",
        f"| baseline | {base.spec.describe()} | | | {_gap_cells(base)} |",
    ]
    for i, step in enumerate(diagnoser.steps_, 1):
        dbic = "cut" if step.delta_bic is None else f"{step.delta_bic:.0f}"
        rows.append(
            f"| {i} | {step.effect.name} | {step.effect.family} | {dbic} | {_gap_cells(step.after)} |"
        )
    coefficients = "\n".join(
        f"| {k} | {v:.6g} | {diagnoser.final_.std.get(k, float('nan')):.2g} |"
        for k, v in diagnoser.final_.coefficients.items()
    )
    text = "\n".join(
        [
            "# Discrepancy diagnosis",
            "",
            f"Runs: {', '.join(p.name for p in base.runs)}",
            "",
            "## Story",
            "",
            *[f"- {line}" for line in story(diagnoser)],
            "",
            "## The gap, step by step",
            "",
            *rows,
            "",
            f"Gap reduction (1 - final RMS / baseline RMS): {100 * diagnoser.gap_reduction_:.1f} %",
            "",
            "## Final model",
            "",
            "| parameter | value | std (white-noise) |",
            "|---|---|---|",
            coefficients,
            "",
            "![measurement, baseline and final model](models.png)",
            "",
            "![residual before and after](residuals.png)",
            "",
            "![residual spectrum](spectrum.png)",
            "",
        ]
    )
    return write_text_new(out / REPORT_FILES[0], text)


def log_to_rerun(diagnoser: Diagnoser, stream: Any) -> None:
    """The same story in the rerun viewer (``viz.diagnose_view.log_diagnosis``): per run the
    measurement, baseline, final model and residuals, and the story as a text log."""
    diagnose_view.log_diagnosis(stream, diagnoser.baseline_.runs, diagnoser.final_.runs, story(diagnoser))


def save_rrd(diagnoser: Diagnoser, path: str | Path) -> Path:
    """``log_to_rerun`` into a new .rrd file (open it with ``rerun path``)."""
    return diagnose_view.save_diagnosis_rrd(
        path, diagnoser.baseline_.runs, diagnoser.final_.runs, story(diagnoser)
    )
