"""The figures and rerun recording of a discrepancy diagnosis (``tankdaq diagnose --report/--rrd``).

``diagnose.report`` owns the story and hands over plain data: per run the model's view
(``PredictedRun``: the time, the predicted angle and the angle residual, in rad; the diagnosis's
``RunPrediction`` is one), the residual spectra (``ResidualSpectrum``) and the story's lines. PNGs are
built like every report figure (``viz.plots``); rerun is imported only when a recording is written.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..errors import InputError
from .plots import MEASURED_COLOR, MODEL_COLOR, report_style


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
        fig = Figure(figsize=(9.0, 1.2 + 2.2 * rows), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(rows, 1, squeeze=False)[:, 0]
    return fig, axes


def models_figure(baseline: Sequence[PredictedRun], final: Sequence[PredictedRun]) -> Figure:
    """Per run: measurement, baseline model and final model, in degrees."""
    with report_style():
        fig, axes = _new_figure(len(baseline))
        for ax, base, last in zip(axes, baseline, final, strict=True):
            measured = base.angle + base.residual_angle
            ax.plot(base.t, np.degrees(measured), color=MEASURED_COLOR, linewidth=0.8, label="measured")
            ax.plot(base.t, np.degrees(base.angle), color="0.5", linestyle=":", label="baseline")
            ax.plot(last.t, np.degrees(last.angle), color=MODEL_COLOR, linestyle="--", label="final")
            ax.set_ylabel(f"{base.name} (deg)")
        axes[0].legend(loc="upper right", ncols=3)
        axes[0].set_title("measurement, baseline and final model")
        axes[-1].set_xlabel("time (s)")
    return fig


def residuals_figure(baseline: Sequence[PredictedRun], final: Sequence[PredictedRun]) -> Figure:
    """Per run: the angle residual of the baseline and of the final model, in degrees."""
    with report_style():
        fig, axes = _new_figure(len(baseline))
        for ax, base, last in zip(axes, baseline, final, strict=True):
            ax.plot(
                base.t, np.degrees(base.residual_angle), color=MEASURED_COLOR, linewidth=0.7, label="baseline"
            )
            ax.plot(last.t, np.degrees(last.residual_angle), color=MODEL_COLOR, linewidth=0.7, label="final")
            ax.axhline(0.0, color="0.4", linewidth=0.6)
            ax.set_ylabel(f"{base.name} (deg)")
        axes[0].legend(loc="upper right", ncols=2)
        axes[0].set_title("residual before and after")
        axes[-1].set_xlabel("time (s)")
    return fig


def spectrum_figure(first: ResidualSpectrum, last: ResidualSpectrum, omega0_rad_s: float) -> Figure:
    """Welch spectrum of the residual, baseline against final, with the natural frequency's first three
    multiples marked (``omega0_rad_s`` 0 when the model has none: no marks, automatic range)."""
    with report_style():
        fig, (ax,) = _new_figure(1)
        ax.semilogy(first.omega_rad_s, np.degrees(np.sqrt(first.psd)), color=MEASURED_COLOR, label="baseline")
        ax.semilogy(last.omega_rad_s, np.degrees(np.sqrt(last.psd)), color=MODEL_COLOR, label="final")
        for k in (1, 2, 3):
            ax.axvline(k * omega0_rad_s, color="0.6", linewidth=0.6, linestyle=":")
        ax.set_xlim(0, 6 * omega0_rad_s if omega0_rad_s > 0 else None)
        ax.set_xlabel("frequency (rad/s); dotted: 1, 2, 3 x natural")
        ax.set_ylabel("residual ASD (deg/sqrt(Hz))")
        ax.legend()
    return fig


def log_diagnosis(
    stream: Any, baseline: Sequence[PredictedRun], final: Sequence[PredictedRun], story: Sequence[str]
) -> None:
    """Per run the measurement, baseline, final model and residuals on the ``t`` timeline (degrees),
    and the story as a text log. ``stream`` is an rr.RecordingStream."""
    import rerun as rr

    from . import live

    styles = {
        "measured": (live.MEASURED_COLOR, 1.0),
        "baseline": ((150, 150, 150), 1.5),
        "final": (live.MODEL_COLOR, 2.0),
    }
    for base, last in zip(baseline, final, strict=True):
        series = {
            f"diagnose/{base.name}/angle/measured": (base.t, base.angle + base.residual_angle, "measured"),
            f"diagnose/{base.name}/angle/baseline": (base.t, base.angle, "baseline"),
            f"diagnose/{base.name}/angle/final": (last.t, last.angle, "final"),
            f"diagnose/{base.name}/residual/baseline": (base.t, base.residual_angle, "baseline"),
            f"diagnose/{base.name}/residual/final": (last.t, last.residual_angle, "final"),
        }
        for entity, (t, values, style) in series.items():
            color, width = styles[style]
            stream.log(entity, rr.SeriesLines(colors=[color], widths=[width], names=[style]), static=True)
            stream.send_columns(
                entity,
                indexes=[rr.TimeColumn(live.TIMELINE, duration=np.asarray(t, dtype=float))],
                columns=rr.Scalars.columns(scalars=np.degrees(np.asarray(values, dtype=float))),
            )
    for line in story:
        stream.log("diagnose/story", rr.TextLog(line, level="INFO"))


def save_diagnosis_rrd(
    path: str | Path, baseline: Sequence[PredictedRun], final: Sequence[PredictedRun], story: Sequence[str]
) -> Path:
    """``log_diagnosis`` into a new .rrd file (open it with ``rerun path``)."""
    import rerun as rr

    from .live import APPLICATION_ID

    path = Path(path)
    if not path.parent.is_dir():
        raise InputError(f"cannot write {path}: folder {path.parent} does not exist")
    stream = rr.RecordingStream(APPLICATION_ID)
    stream.save(str(path))
    log_diagnosis(stream, baseline, final, story)
    stream.flush()
    stream.disconnect()
    return path
