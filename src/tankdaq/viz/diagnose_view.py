"""The figures and rerun recording of a discrepancy diagnosis (``tankdaq diagnose --report/--rrd``).

``diagnose.report`` owns the story and hands over plain data: per run the model's view
(``PredictedRun``: the time, the predicted angle and the angle residual, in rad; the diagnosis's
``RunPrediction`` is one), the residual spectra (``ResidualSpectrum``) and the story's lines. PNGs are
built like every report figure (``viz.plots``); rerun is imported only when a recording is written.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..errors import InputError
from ..ident.interval_labels import FIT_95
from ..store.safe_write import new_path
from .plots import MEASURED_COLOR, MODEL_COLOR, interval_caption, legend_beside, report_style, short_labels


class PredictedRun(Protocol):
    """One run as a model sees it; the measurement is ``angle + residual_angle``."""

    @property
    def name(self) -> str: ...
    @property
    def t(self) -> np.ndarray: ...
    @property
    def angle(self) -> np.ndarray: ...
    @property
    def residual_angle(self) -> np.ndarray: ...


class ResidualSpectrum(Protocol):
    """A residual's power spectral density (rad^2 per Hz) against frequency (rad/s)."""

    @property
    def omega_rad_s(self) -> np.ndarray: ...
    @property
    def psd(self) -> np.ndarray: ...


def _new_figure(rows: int) -> tuple[Figure, np.ndarray]:
    with report_style():
        fig = Figure(figsize=(9.0, 1.6 + 2.2 * rows), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(rows, 1, squeeze=False, sharex=True)[:, 0]
    return fig, axes


def _since_release(run: PredictedRun) -> np.ndarray:
    """The run's time from its first free sample (the fitted decay starts at the release), s."""
    t = np.asarray(run.t, dtype=float)
    return t - t[0]


def _per_run(
    fig: Figure, axes: np.ndarray, labels: Sequence[str], ylabel: str, title: str, legend: Sequence[str]
) -> None:
    """Each panel named by its run (a short label above it, never a long y-label), one legend for the
    figure right of the panels, the time since release under the last."""
    for ax, label in zip(axes, labels, strict=True):
        ax.set_title(label, loc="left", fontsize=9)
        ax.set_ylabel(ylabel)
    fig.suptitle(title)
    fig.legend(axes[0].lines[: len(legend)], legend, loc="outside right upper")
    axes[-1].set_xlabel("time since release (s)")


def models_figure(
    baseline: Sequence[PredictedRun], final: Sequence[PredictedRun], labels: Sequence[str] | None = None
) -> Figure:
    """Per run: measurement, baseline model and final model, in degrees, against the time since release
    (``labels``: a short one per run, ``run_labels``; default ``short_labels`` of the names)."""
    with report_style():
        fig, axes = _new_figure(len(baseline))
        for ax, base, last in zip(axes, baseline, final, strict=True):
            t = _since_release(base)
            measured = base.angle + base.residual_angle
            ax.plot(t, np.degrees(measured), color=MEASURED_COLOR, linewidth=0.8)
            ax.plot(t, np.degrees(base.angle), color="0.5", linestyle=":")
            ax.plot(_since_release(last), np.degrees(last.angle), color=MODEL_COLOR, linestyle="--")
        names = labels or short_labels([run.name for run in baseline])
        legend = ["measured", "baseline", "final"]
        _per_run(fig, axes, names, "angle (deg)", "measurement, baseline and final model", legend)
    return fig


def residuals_figure(
    baseline: Sequence[PredictedRun], final: Sequence[PredictedRun], labels: Sequence[str] | None = None
) -> Figure:
    """Per run: the angle residual of the baseline and of the final model, in degrees, against the time
    since release."""
    with report_style():
        fig, axes = _new_figure(len(baseline))
        for ax, base, last in zip(axes, baseline, final, strict=True):
            ax.plot(
                _since_release(base), np.degrees(base.residual_angle), color=MEASURED_COLOR, linewidth=0.7
            )
            ax.plot(_since_release(last), np.degrees(last.residual_angle), color=MODEL_COLOR, linewidth=0.7)
            ax.axhline(0.0, color="0.4", linewidth=0.6)
        names = labels or short_labels([run.name for run in baseline])
        _per_run(fig, axes, names, "residual (deg)", "residual before and after", ["baseline", "final"])
    return fig


def spectrum_figure(first: ResidualSpectrum, last: ResidualSpectrum, omega0_rad_s: float) -> Figure:
    """Amplitude spectral density of the residual (deg/√Hz) against frequency (Hz), baseline against
    final, with the natural frequency's first three multiples marked (``omega0_rad_s`` 0 when the model
    has none: no marks, automatic range). The spectra come zero-padded (``diagnose.residuals``): a smooth
    curve at the Welch segments' resolution."""
    f0_hz = omega0_rad_s / (2 * np.pi)
    with report_style():
        fig, (ax,) = _new_figure(1)
        for spectrum, color, label in ((first, MEASURED_COLOR, "baseline"), (last, MODEL_COLOR, "final")):
            frequency_hz = np.asarray(spectrum.omega_rad_s) / (2 * np.pi)
            ax.semilogy(frequency_hz, np.degrees(np.sqrt(spectrum.psd)), color=color, label=label)
        for k in (1, 2, 3):
            if f0_hz > 0:
                ax.axvline(k * f0_hz, color="0.6", linewidth=0.6, linestyle=":")
        ax.set_xlim(0, 6 * f0_hz if f0_hz > 0 else None)
        ax.set_xlabel("frequency (Hz); dotted: 1, 2, 3 x natural" if f0_hz > 0 else "frequency (Hz)")
        ax.set_ylabel("residual ASD (deg/√Hz)")
        ax.set_title("residual spectrum")
        legend_beside(ax)
    return fig


def log_diagnosis(
    stream: Any, baseline: Sequence[PredictedRun], final: Sequence[PredictedRun], story: Sequence[str]
) -> None:
    """Per run the measurement, baseline, final model and residuals on the ``t`` timeline (time since
    release, degrees), and the story as a text log. ``stream`` is an rr.RecordingStream."""
    import rerun as rr

    from . import live

    styles = {
        "measured": (live.MEASURED_COLOR, 1.0),
        "baseline": ((150, 150, 150), 1.5),
        "final": (live.MODEL_COLOR, 2.0),
    }
    for base, last in zip(baseline, final, strict=True):
        t, t_final = _since_release(base), _since_release(last)
        series = {
            f"diagnose/{base.name}/angle/measured": (t, base.angle + base.residual_angle, "measured"),
            f"diagnose/{base.name}/angle/baseline": (t, base.angle, "baseline"),
            f"diagnose/{base.name}/angle/final": (t_final, last.angle, "final"),
            f"diagnose/{base.name}/residual/baseline": (t, base.residual_angle, "baseline"),
            f"diagnose/{base.name}/residual/final": (t_final, last.residual_angle, "final"),
        }
        _log_series(stream, series, styles)
    for line in story:
        stream.log("diagnose/story", rr.TextLog(line, level="INFO"))


def _log_series(
    stream: Any, series: dict[str, tuple[np.ndarray, np.ndarray, str]], styles: dict[str, tuple[Any, float]]
) -> None:
    """Each entity's (t, angle in rad, style) as a styled line of degrees on the ``t`` timeline."""
    import rerun as rr

    from .live import TIMELINE

    for entity, (t, values, style) in series.items():
        color, width = styles[style]
        stream.log(entity, rr.SeriesLines(colors=[color], widths=[width], names=[style]), static=True)
        stream.send_columns(
            entity,
            indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=float))],
            columns=rr.Scalars.columns(scalars=np.degrees(np.asarray(values, dtype=float))),
        )


def save_diagnosis_rrd(
    path: str | Path, baseline: Sequence[PredictedRun], final: Sequence[PredictedRun], story: Sequence[str]
) -> Path:
    """``log_diagnosis`` into a new .rrd file (open it with ``rerun path``)."""
    return _write_rrd(path, lambda stream: log_diagnosis(stream, baseline, final, story))


def _write_rrd(path: str | Path, log: Callable[[Any], None]) -> Path:
    """A new .rrd file at ``path`` holding what ``log`` logs to the stream it is given."""
    import rerun as rr

    from .live import APPLICATION_ID

    path = Path(path)
    if not path.parent.is_dir():
        raise InputError(f"cannot write {path}: folder {path.parent} does not exist")
    with new_path(path) as temporary:  # never over a file, never half-written under its name
        stream = rr.RecordingStream(APPLICATION_ID)
        stream.save(str(temporary))
        log(stream)
        stream.flush()
        stream.disconnect()
    return path


#: The simulation's colour beside the measured (blue) and the corrected model (red).
SIMULATION_COLOR = "#ff7f0e"


def simulation_figure(
    simulation: Sequence[PredictedRun],
    corrected: Sequence[PredictedRun],
    labels: Sequence[str],
    gap_deg: tuple[float, float],
) -> Figure:
    """Per run, side by side: measured, simulation and corrected angle against the time since release,
    and the gap of each to the measurement (``gap_deg``: RMS before and after, in the title). Each row is
    named by its run's label above its left panel (a y-label of a long name would be cut)."""
    with report_style():
        fig = Figure(figsize=(11.0, 1.6 + 2.4 * len(simulation)), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(len(simulation), 2, squeeze=False, sharex=True, width_ratios=(3, 2))
        for (left, right), sim, fixed, label in zip(axes, simulation, corrected, labels, strict=True):
            t = np.asarray(sim.t) - sim.t[0]
            left.plot(t, np.degrees(sim.angle + sim.residual_angle), color=MEASURED_COLOR, linewidth=0.8)
            left.plot(t, np.degrees(sim.angle), color=SIMULATION_COLOR, linestyle=":")
            left.plot(t, np.degrees(fixed.angle), color=MODEL_COLOR, linestyle="--", linewidth=1.0)
            left.set_title(label, loc="left", fontsize=9)
            left.set_ylabel("angle (deg)")
            right.plot(t, np.degrees(sim.residual_angle), color=SIMULATION_COLOR, linewidth=0.7)
            right.plot(t, np.degrees(fixed.residual_angle), color=MODEL_COLOR, linewidth=0.7)
            right.axhline(0.0, color="0.4", linewidth=0.6)
            right.set_ylabel("measured minus model (deg)")
        fig.suptitle(
            "angle from the measured release, and measured minus model: "
            f"RMS {gap_deg[0]:.3g} -> {gap_deg[1]:.3g} deg"
        )
        for ax in axes[-1]:
            ax.set_xlabel("time since release (s)")
        fig.legend(
            axes[0, 0].lines,
            ["measured", "simulation", "corrected"],
            loc="outside lower center",
            ncols=3,
        )
    return fig


def damping_figure(
    amplitudes_deg: Sequence[float],
    b_eq: dict[str, tuple[np.ndarray, np.ndarray]],
    decrements: dict[str, tuple[np.ndarray, np.ndarray]],
    b44_hat_per_b_eq: float | None = None,
) -> Figure:
    """B_eq(phi_a) with bands ± (95 %, fit) (``b_eq``: name -> value, std in 1/s) and the decrement per half
    cycle against the mean amplitude (``decrements``: name -> amplitude, decrement in rad), side by side;
    names are measured, simulation and corrected. ``b44_hat_per_b_eq`` (I √(B/2g) / (ρ∇B²), where the
    hull gives them) adds B̂44's scale beside B_eq/I."""
    colors = {"measured": MEASURED_COLOR, "simulation": SIMULATION_COLOR, "corrected": MODEL_COLOR}
    markers = {"measured": "o", "simulation": "s", "corrected": "^"}
    with report_style():
        fig = Figure(figsize=(11.0, 3.8), layout="constrained")
        FigureCanvasAgg(fig)
        left, right = fig.subplots(1, 2)
        amplitudes = np.asarray(amplitudes_deg, dtype=float)
        for name, (value, std) in b_eq.items():
            left.plot(amplitudes, value, color=colors[name], marker=markers[name], label=name)
            half = FIT_95.half_width(1.0) * std
            left.fill_between(amplitudes, value - half, value + half, color=colors[name], alpha=0.2)
        left.set_xlabel("amplitude (deg)")
        left.set_ylabel("B_eq / I (1/s)")
        if b44_hat_per_b_eq is not None:
            k = b44_hat_per_b_eq
            hat = left.secondary_yaxis("right", functions=(lambda b: b * k, lambda h: h / k))
            hat.set_ylabel("B̂44 = B44 √(B/2g) / (ρ∇B²)")
        left.set_title(f"equivalent linear damping ({interval_caption(FIT_95, 'bands')})")
        for name, (amplitude, decrement) in decrements.items():
            right.plot(
                np.degrees(amplitude),
                np.degrees(decrement),
                linestyle="none",
                color=colors[name],
                marker=markers[name],
                markersize=3,
                label=name,
            )
        right.set_xlabel("mean amplitude (deg)")
        right.set_ylabel("decrement per half cycle (deg)")
        right.set_title("extinction curve")
        fig.legend(*left.get_legend_handles_labels(), loc="outside upper center", ncols=3)
    return fig


def log_simulation(
    stream: Any,
    simulation: Sequence[PredictedRun],
    corrected: Sequence[PredictedRun],
    labels: Sequence[str],
    story: Sequence[str],
) -> None:
    """Per run the measured, simulated and corrected angle and the gaps, on the ``t`` timeline (time
    since release, degrees), and the story as a text log. ``stream`` is an rr.RecordingStream."""
    import rerun as rr

    from . import live

    styles = {
        "measured": (live.MEASURED_COLOR, 1.0),
        "simulation": ((255, 127, 14), 1.5),
        "corrected": (live.MODEL_COLOR, 2.0),
    }
    for sim, fixed, label in zip(simulation, corrected, labels, strict=True):
        t = np.asarray(sim.t, dtype=float) - sim.t[0]
        series = {
            f"simulate/{label}/angle/measured": (t, sim.angle + sim.residual_angle, "measured"),
            f"simulate/{label}/angle/simulation": (t, sim.angle, "simulation"),
            f"simulate/{label}/angle/corrected": (t, fixed.angle, "corrected"),
            f"simulate/{label}/gap/simulation": (t, sim.residual_angle, "simulation"),
            f"simulate/{label}/gap/corrected": (t, fixed.residual_angle, "corrected"),
        }
        _log_series(stream, series, styles)
    for line in story:
        stream.log("simulate/story", rr.TextLog(line, level="INFO"))


def save_simulation_rrd(
    path: str | Path,
    simulation: Sequence[PredictedRun],
    corrected: Sequence[PredictedRun],
    labels: Sequence[str],
    story: Sequence[str],
) -> Path:
    """``log_simulation`` into a new .rrd file (open it with ``rerun path``)."""
    return _write_rrd(path, lambda stream: log_simulation(stream, simulation, corrected, labels, story))
