"""PNG figures for reports: a decay with its model and residual, and series with error bars.

Figures are built on ``matplotlib.figure.Figure`` with the Agg canvas, never
pyplot, so they hold no global state and work on a headless lab PC or in
threads. Inputs are SI (rad, rad/s); degrees appear only on the axes.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib as mpl
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..errors import RecordingError
from ..ident.conditions import UNKNOWN, condition_of
from ..ident.interval_labels import IntervalLabel
from ..records import DecayRun
from ..store.naming import parse_recording_name
from ..store.safe_write import write_new

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.legend import Legend
    from matplotlib.typing import RcKeyType

MEASURED_COLOR = "#1f77b4"
MODEL_COLOR = "#d62728"
STYLE: dict[RcKeyType, Any] = {
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "font.size": 10,
    "axes.titlesize": 11,
    "legend.frameon": False,
    "lines.linewidth": 1.2,
    # Titles sit just above their axes (none of ours has top tick labels): matplotlib's automatic
    # placement measured every axes' tight box at each draw, 5-10 % of a campaign report's drawing,
    # for the same pixels.
    "axes.titley": 1.0,
}


@contextmanager
def report_style() -> Iterator[None]:
    """The one look of every tankdaq figure (applied while the figure is built)."""
    with mpl.rc_context(STYLE):
        yield


def legend_beside(ax: Axes, **kwargs: Any) -> Legend:
    """``ax``'s legend right of it, outside the data: the layout engine (constrained) makes room for it.
    Every legend of a report figure is outside its axes or in the figure's own margin, never on data."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kwargs)


def interval_caption(label: IntervalLabel, what: str = "bars") -> str:
    """What a figure says of its intervals, in its legend or title: ``bars: ± (95 %, fit)``."""
    return f"{what}: {label}"


def _figure(
    rows: int, height_ratios: Sequence[float] | None = None, sharex: bool = True
) -> tuple[Figure, list]:
    fig = Figure(figsize=(8.0, 2.2 + 2.0 * rows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, sharex=sharex, squeeze=False, height_ratios=height_ratios)[:, 0]
    return fig, list(axes)


def decay_fit_figure(
    t_s: np.ndarray,
    angle_rad: np.ndarray,
    model_angle_rad: np.ndarray | None = None,
    *,
    axis: str = "roll",
    title: str | None = None,
    model_label: str = "model",
    xlabel: str = "time since release (s)",
) -> Figure:
    """Measured decay with the model drawn over it and, with a model, the residual underneath (``t_s``
    the time since release, as every decay figure draws it)."""
    t_s = np.asarray(t_s, dtype=float)
    measured_deg = np.degrees(np.asarray(angle_rad, dtype=float))
    with report_style():
        fig, axes = _figure(
            2 if model_angle_rad is not None else 1, [3, 1] if model_angle_rad is not None else None
        )
        top = axes[0]
        top.plot(t_s, measured_deg, color=MEASURED_COLOR, label="measured")
        top.set_ylabel(f"{axis} angle (deg)")
        if model_angle_rad is not None:
            model_deg = np.degrees(np.asarray(model_angle_rad, dtype=float))
            top.plot(t_s, model_deg, color=MODEL_COLOR, linestyle="--", label=model_label)
            residual = axes[1]
            residual.plot(t_s, measured_deg - model_deg, color=MEASURED_COLOR, linewidth=0.8)
            residual.axhline(0.0, color="0.4", linewidth=0.6)
            residual.set_ylabel("residual (deg)")
        axes[-1].set_xlabel(xlabel)
        legend_beside(top)
        if title:
            top.set_title(title)
    return fig


def series_figure(
    x: np.ndarray,
    series: Mapping[str, tuple[np.ndarray, np.ndarray | None]],
    *,
    xlabel: str,
    ylabel: str,
    title: str | None = None,
    interval: IntervalLabel | None = None,
) -> Figure:
    """Several named series against one x, each with optional symmetric error bars (``(y, yerr)``), whose
    ``interval`` (coverage and kind) the title says: bars without one are refused.

    Labels must carry their units, e.g. ``xlabel="amplitude (deg)"``.
    """
    bars = any(yerr is not None for _, yerr in series.values())
    if bars and interval is None:
        raise ValueError("series_figure: error bars need their interval (coverage and kind) to say")
    caption = interval_caption(interval) if bars and interval is not None else None
    with report_style():
        fig, (ax,) = _figure(1)
        for label, (y, yerr) in series.items():
            ax.errorbar(x, y, yerr=yerr, marker="o", markersize=4, capsize=3, label=label)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        if len(series) > 1:
            legend_beside(ax)
        if title or caption:
            ax.set_title(" ".join(part for part in (title, f"({caption})" if caption else None) if part))
    return fig


#: The longest run label a figure or the viewer shows.
LABEL_CHARS = 16


def short_labels(names: Sequence[str]) -> list[str]:
    """Labels that tell the runs apart in a panel and name rerun entities: the shortest unique tail of
    their names' tokens (``model_test_21338`` -> ``21338``, ``stem#2`` -> ``stem_2``, not a bare part
    number), at most ``LABEL_CHARS`` long, else ``runN``."""
    tokens = [[t for t in re.split(r"[\s_/\\:.#-]+", name) if t] for name in names]
    for count in range(1, max((len(t) for t in tokens), default=1) + 1):
        labels = ["_".join(t[-count:]) for t in tokens]
        readable = all(0 < len(lb) <= LABEL_CHARS and not (lb.isdigit() and len(lb) <= 2) for lb in labels)
        if len(set(labels)) == len(labels) and readable:
            return labels
    return [f"run{i + 1}" for i in range(len(names))]


def run_labels(runs: Sequence[DecayRun]) -> list[str]:
    """What a person calls each run: its condition and run number (``swath T roll #3``; a record's
    second decay ``#3.2``) from the recording's metadata and name; where that does not tell every run
    apart, ``short_labels`` of the names."""
    labels = []
    for run in runs:
        condition = condition_of(run)
        named = parse_recording_name(Path(str(run.meta.get("file", run.name))).name)
        part = run.name.rpartition("#")[2] if "#" in run.name else ""
        number = f" #{named.run}" if named is not None and named.run is not None else ""
        known = condition.hull != UNKNOWN and condition.draft != UNKNOWN
        labels.append(f"{condition.label}{number}{'.' + part if number and part else ''}" if known else "")
    if all(labels) and len(set(labels)) == len(labels):
        return labels
    return short_labels([run.name for run in runs])


def save_png(fig: Figure, path: str | Path, dpi: int = 150) -> Path:
    """Write ``fig`` as a new PNG file (``store.safe_write``: never over a file, never half-written)."""
    path = Path(path)
    if not path.parent.is_dir():
        raise RecordingError(f"cannot write {path}: folder {path.parent} does not exist")
    return write_new(path, lambda out: fig.savefig(out, dpi=dpi, format="png"))


def save_decay_fits(runs: Sequence[DecayRun], predicted: Sequence[np.ndarray], folder: Path) -> list[Path]:
    """One PNG per decay (measured, model, residual), named after the decay's file, in ``folder``; its
    title is the run's short label (``run_labels``)."""
    written = []
    for run, model_angle, label in zip(runs, predicted, run_labels(runs), strict=True):
        stem = Path(str(run.meta.get("file", run.name))).stem
        figure = decay_fit_figure(run.t - run.t[0], run.angle, model_angle, axis=run.axis, title=label)
        written.append(save_png(figure, folder / f"{stem}.png"))
    return written
