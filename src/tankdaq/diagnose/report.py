"""The story of a diagnosis, told four ways: terminal lines, JSON, a Markdown report with PNGs, rerun.

All of them read a fitted ``Diagnoser``; angles are converted to degrees here
and only here.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..errors import InputError, RecordingError
from ..ident.free_decay import cut_lines
from .fitting import Fit
from .residuals import SPECTRUM_MEANING
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


def _diagnostics_summary(diag: Diagnostics) -> dict[str, Any]:
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
        "diagnostics_before": _diagnostics_summary(step.diagnostics),
    }


def summary(diagnoser: Diagnoser) -> dict[str, Any]:
    """The JSON document of ``tankdaq diagnose --json``."""
    base, final = diagnoser.baseline_, diagnoser.final_
    trend = diagnoser.cycle_trend_
    return {
        "runs": [p.name for p in base.runs],
        "cuts": [run.meta.get("cut") for run in diagnoser.runs_],
        "baseline": {**_fit_summary(base), "diagnostics": _diagnostics_summary(diagnoser.diagnostics_[0])},
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
    }


def _finite(value: Any) -> Any:
    """JSON has no NaN: undefined numbers (a std of a degenerate fit) become null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def summary_json(diagnoser: Diagnoser) -> str:
    """``summary`` as one line of valid JSON."""
    return json.dumps(_finite(summary(diagnoser)))


def _step_line(step: Step, diagnoser: Diagnoser) -> str:
    effect = step.effect
    after = step.after
    if effect.kind == "truncation":
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
    return [f"cut: {line}" for line in cut_lines(diagnoser.runs_)] + lines


# ---------------------------------------------------------------------------------------------- figures


def _new_figure(rows: int) -> tuple[Figure, np.ndarray]:
    from ..viz.plots import report_style

    with report_style():
        fig = Figure(figsize=(9.0, 1.2 + 2.2 * rows), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(rows, 1, squeeze=False)[:, 0]
    return fig, axes


def models_figure(diagnoser: Diagnoser) -> Figure:
    """Per run: measurement, baseline model and final model, in degrees."""
    from ..viz.plots import MEASURED_COLOR, MODEL_COLOR, report_style

    base_runs, final_runs = diagnoser.baseline_.runs, diagnoser.final_.runs
    with report_style():
        fig, axes = _new_figure(len(base_runs))
        for ax, base, final in zip(axes, base_runs, final_runs, strict=True):
            measured = base.angle + base.residual_angle
            ax.plot(base.t, np.degrees(measured), color=MEASURED_COLOR, linewidth=0.8, label="measured")
            ax.plot(base.t, np.degrees(base.angle), color="0.5", linestyle=":", label="baseline")
            ax.plot(final.t, np.degrees(final.angle), color=MODEL_COLOR, linestyle="--", label="final")
            ax.set_ylabel(f"{base.name} (deg)")
        axes[0].legend(loc="upper right", ncols=3)
        axes[0].set_title("measurement, baseline and final model")
        axes[-1].set_xlabel("time (s)")
    return fig


def residuals_figure(diagnoser: Diagnoser) -> Figure:
    """Per run: the angle residual of the baseline and of the final model, in degrees."""
    from ..viz.plots import MEASURED_COLOR, MODEL_COLOR, report_style

    with report_style():
        fig, axes = _new_figure(len(diagnoser.baseline_.runs))
        for ax, base, final in zip(axes, diagnoser.baseline_.runs, diagnoser.final_.runs, strict=True):
            ax.plot(
                base.t, np.degrees(base.residual_angle), color=MEASURED_COLOR, linewidth=0.7, label="baseline"
            )
            ax.plot(
                final.t, np.degrees(final.residual_angle), color=MODEL_COLOR, linewidth=0.7, label="final"
            )
            ax.axhline(0.0, color="0.4", linewidth=0.6)
            ax.set_ylabel(f"{base.name} (deg)")
        axes[0].legend(loc="upper right", ncols=2)
        axes[0].set_title("residual before and after")
        axes[-1].set_xlabel("time (s)")
    return fig


def spectrum_figure(diagnoser: Diagnoser) -> Figure:
    """Welch spectrum of the residual, baseline against final, with the natural frequency marked."""
    from ..viz.plots import MEASURED_COLOR, MODEL_COLOR, report_style

    first, last = diagnoser.diagnostics_[0].spectrum, diagnoser.diagnostics_[-1].spectrum
    omega0 = float(
        np.sqrt(
            max(diagnoser.final_.coefficients.get("c1", 0) + diagnoser.final_.coefficients.get("s1", 0), 0)
        )
    )
    with report_style():
        fig, (ax,) = _new_figure(1)
        ax.semilogy(first.omega_rad_s, np.degrees(np.sqrt(first.psd)), color=MEASURED_COLOR, label="baseline")
        ax.semilogy(last.omega_rad_s, np.degrees(np.sqrt(last.psd)), color=MODEL_COLOR, label="final")
        for k in (1, 2, 3):
            ax.axvline(k * omega0, color="0.6", linewidth=0.6, linestyle=":")
        ax.set_xlim(0, 6 * omega0 if omega0 > 0 else None)
        ax.set_xlabel("frequency (rad/s); dotted: 1, 2, 3 x natural")
        ax.set_ylabel("residual ASD (deg/sqrt(Hz))")
        ax.legend()
    return fig


def _gap_cells(fit: Fit) -> str:
    rate = "n/a | n/a" if fit.rms_rate is None else f"{_deg(fit.rms_rate):.4f} | {fit.nrmse_rate:.4f}"
    return (
        f"{_deg(fit.rms_angle):.4f} | {fit.nrmse_angle:.4f} | {rate} | {fit.fit_percent:.2f} "
        f"| {fit.ljung_box_p:.3g}"
    )


def write_report(diagnoser: Diagnoser, directory: str | Path) -> Path:
    """``directory/diagnose.md`` with the story, a step table and three PNG figures."""
    from ..viz.plots import save_png

    out = Path(directory)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordingError(f"cannot create report folder {out}: {exc.strerror or exc}") from None
    figures = {
        "models.png": models_figure(diagnoser),
        "residuals.png": residuals_figure(diagnoser),
        "spectrum.png": spectrum_figure(diagnoser),
    }
    for name, fig in figures.items():
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
    path = out / "diagnose.md"
    try:
        path.write_text(text)
    except OSError as exc:
        raise RecordingError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def log_to_rerun(diagnoser: Diagnoser, stream: Any) -> None:
    """The same story in the rerun viewer: per run the measurement, baseline, final model and residuals
    on the ``t`` timeline (degrees), and the story as a text log. ``stream`` is an rr.RecordingStream."""
    import rerun as rr

    from ..viz.live import MEASURED_COLOR, MODEL_COLOR, TIMELINE

    styles = {
        "measured": (MEASURED_COLOR, 1.0),
        "baseline": ((150, 150, 150), 1.5),
        "final": (MODEL_COLOR, 2.0),
    }
    for base, final in zip(diagnoser.baseline_.runs, diagnoser.final_.runs, strict=True):
        series = {
            f"diagnose/{base.name}/angle/measured": (base.t, base.angle + base.residual_angle, "measured"),
            f"diagnose/{base.name}/angle/baseline": (base.t, base.angle, "baseline"),
            f"diagnose/{base.name}/angle/final": (final.t, final.angle, "final"),
            f"diagnose/{base.name}/residual/baseline": (base.t, base.residual_angle, "baseline"),
            f"diagnose/{base.name}/residual/final": (final.t, final.residual_angle, "final"),
        }
        for entity, (t, values, style) in series.items():
            color, width = styles[style]
            stream.log(entity, rr.SeriesLines(colors=[color], widths=[width], names=[style]), static=True)
            stream.send_columns(
                entity,
                indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=float))],
                columns=rr.Scalars.columns(scalars=np.degrees(np.asarray(values, dtype=float))),
            )
    for line in story(diagnoser):
        stream.log("diagnose/story", rr.TextLog(line, level="INFO"))


def save_rrd(diagnoser: Diagnoser, path: str | Path) -> Path:
    """``log_to_rerun`` into a new .rrd file (open it with ``rerun path``)."""
    import rerun as rr

    from ..viz.live import APPLICATION_ID

    path = Path(path)
    if not path.parent.is_dir():
        raise InputError(f"cannot write {path}: folder {path.parent} does not exist")
    stream = rr.RecordingStream(APPLICATION_ID)
    stream.save(str(path))
    log_to_rerun(diagnoser, stream)
    stream.flush()
    stream.disconnect()
    return path
