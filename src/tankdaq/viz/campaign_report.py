"""A campaign's report: its tables (``campaign.groups``) and its figures, one PNG each, drawn here.

``campaign.groups`` returns data (group fits, tables); this module draws the seeds' figures and the
ITTC ones from it. Each figure is one unit of work (``draw_plot``: groups in, PNG out), so a report's
figures are drawn in parallel on the campaign's executor. Figures have fixed margins (no layout
engine): constrained layout drew every figure twice, a layout pass and the real one, for 40 % of
the report's time.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..campaign.executors import executor_map, send_once
from ..campaign.groups import REPORT_TABLES, GroupKey, GroupResult, write_tables
from ..config.hulls import format_draft
from ..config.rules import path_in
from ..ident.derived import b_eq_band, extinction_curve, natural_period
from ..ident.imo_table import initial_angle_deg
from ..ident.interval_labels import ANGLES_RANGE, FIT_95
from ..ident.output_error import OutputErrorFit
from ..physics.terms import TERM_TABLE
from ..store.safe_write import refuse_existing
from .plots import interval_caption, report_style, save_png

#: Margins in inches: room for the tick labels and axis label (left, bottom), the figure's title
#: (top) and the panels' titles above their axes, and the tick labels between panels (gap).
LEFT_IN, RIGHT_IN, BOTTOM_IN, TOP_IN, PANEL_TITLE_IN, GAP_IN = 0.8, 0.2, 0.55, 0.45, 0.25, 0.75
PANEL_WIDTH_IN, HEIGHT_IN = 3.6, 3.2
#: Between the last panel's edge and its legend (in the margin right of the panels).
LEGEND_GAP_IN = 0.2
DPI = 110
#: The figures with a panel per coefficient, which take longest to draw.
MULTI_PANEL = ("coefficients", "hulls")


def load_plotting() -> None:
    """Import matplotlib's figure and Agg canvas now (``campaign_executor(prepare=...)``: before a
    process pool forks, so its workers do not import them once each)."""
    import matplotlib.backends.backend_agg  # noqa: F401  (loaded for the workers)


def write_report(
    results: Sequence[GroupResult], folder: Path, executor: Executor | None = None
) -> list[Path]:
    """campaign.csv, campaign.md and the PNG figures into ``folder`` (created); the files written.

    ``executor`` (``campaign.executors.campaign_executor``) draws the figures in parallel.
    Every file is new (``store.safe_write``): a name that exists is refused before anything is written.
    """
    fitted = [r for r in results if r.fit is not None]
    names = [*REPORT_TABLES, *(name for _, _, name in _figures(fitted))]
    refuse_existing([path_in(folder, name) for name in names])
    return write_tables(results, folder) + write_plots(fitted, folder, executor)


def write_plots(results: Sequence[GroupResult], folder: Path, executor: Executor | None = None) -> list[Path]:
    """The seeds' figures and the ITTC ones, one PNG each, in tankdaq's report style (no display needed)."""
    figures = _figures(results)
    plots = [plot for plot, _, _ in figures]
    each = {id(result): result for _, series, _ in figures for result in series}  # a fit in 3-5 figures
    sent = dict(zip(each, send_once(executor, list(each.values())), strict=True))
    groups = [[sent[id(result)] for result in series] for _, series, _ in figures]
    paths = [path_in(folder, name) for _, _, name in figures]  # a name never leaves the report folder
    return list(executor_map(executor, draw_plot, plots, groups, paths))


def _figures(results: Sequence[GroupResult]) -> list[tuple[str, list[GroupResult], str]]:
    """The report's figures: (plot, its groups, file name), the longest to draw first."""
    figures: list[tuple[str, list[GroupResult], str]] = []
    by_series: dict[tuple[str, str], list[GroupResult]] = defaultdict(list)
    for result in results:
        by_series[(result.key.hull, result.key.axis)].append(result)
    for (hull, axis), series in sorted(by_series.items()):
        figures.append(("coefficients", series, f"coefficients_{hull}_{axis}.png"))
        figures.append(("b_eq", series, f"b_eq_{hull}_{axis}.png"))
        figures.append(("extinction", series, f"extinction_{hull}_{axis}.png"))
    for axis in sorted({r.key.axis for r in results}):
        on_axis = [r for r in results if r.key.axis == axis]
        figures.append(("period", on_axis, f"period_vs_draft_{axis}.png"))
        shared = _shared_draft(on_axis)
        if shared is not None:
            compared = [r for r in on_axis if r.key.draft == shared]
            figures.append(("hulls", compared, f"hulls_{axis}_{format_draft(shared)}.png"))
    figures.sort(key=lambda figure: figure[0] not in MULTI_PANEL)  # the longest first: no long last one
    return figures


def draw_plot(plot: str, results: Sequence[GroupResult], path: Path) -> Path:
    """Draw one report figure and save it as PNG (a unit of work: groups in, file out)."""
    with report_style():
        figure = _PLOTS[plot](results)
    return save_png(figure, path, dpi=DPI)


def _figure(ncols: int, title: str, panel_titles: bool = False) -> tuple[Figure, list[Axes]]:
    width = PANEL_WIDTH_IN * ncols
    top = TOP_IN + (PANEL_TITLE_IN if panel_titles else 0.0)
    panel = (width - LEFT_IN - RIGHT_IN - GAP_IN * (ncols - 1)) / ncols
    fig = Figure(figsize=(width, HEIGHT_IN))
    FigureCanvasAgg(fig)  # the legend's width is measured with its renderer
    fig.subplots_adjust(
        left=LEFT_IN / width,
        right=1.0 - RIGHT_IN / width,
        bottom=BOTTOM_IN / HEIGHT_IN,
        top=1.0 - top / HEIGHT_IN,
        wspace=GAP_IN / panel,
    )
    axes = list(fig.subplots(1, ncols, squeeze=False)[0])
    fig.suptitle(title)
    return fig, axes


def _legend_beside(fig: Figure, axes: Sequence[Axes], title: str | None = None) -> None:
    """The figure's one legend right of its panels, in a margin the figure grows by to fit it: a legend
    never covers data, however long its labels (hull names). The panels keep their size in inches."""
    handles, labels = max((ax.get_legend_handles_labels() for ax in axes), key=lambda hl: len(hl[1]))
    width, height = fig.get_size_inches()
    params = fig.subplotpars
    legend = fig.legend(handles, labels, title=title, loc="upper left", borderaxespad=0.0)
    extra = legend.get_window_extent(fig.canvas.get_renderer()).width / fig.dpi + LEGEND_GAP_IN  # type: ignore[attr-defined]
    wide = width + extra
    fig.set_size_inches(wide, height)
    right_in = (1.0 - params.right) * width
    fig.subplots_adjust(left=params.left * width / wide, right=1.0 - (right_in + extra) / wide)
    legend.set_bbox_to_anchor((1.0 - (right_in + extra - LEGEND_GAP_IN) / wide, params.top))


def _fit(result: GroupResult) -> OutputErrorFit:
    """The group's fit (the report draws fitted groups only)."""
    if result.fit is None:
        raise ValueError(f"{result.key.label} has no fit to draw")
    return result.fit


def _terms(results: Sequence[GroupResult]) -> list[str]:
    return list(dict.fromkeys(t for r in results for t in _fit(r).terms_))


def _measured_angle(result: GroupResult) -> float:
    """The group's initial angle as its decays measured it (deg), not the nominal one its key holds."""
    return initial_angle_deg(result.runs, _fit(result).offsets_)


def _errorbar_series(ax: Axes, points: Sequence[GroupResult], term: str, label: str) -> None:
    points = sorted((r for r in points if term in _fit(r).coefficients_), key=lambda r: r.key.angle_deg)
    ax.errorbar(
        [_measured_angle(r) for r in points],
        [_fit(r).coefficients_[term] for r in points],
        yerr=[FIT_95.half_width(_fit(r).std_[term]) for r in points],
        marker="o",
        capsize=3,
        label=label,
    )


def _plot_coefficients(series: Sequence[GroupResult]) -> Figure:
    """Each coefficient against the measured initial angle, one line per draft (the seeds' Fig. 5), bars
    ± (95 %, fit)."""
    first = series[0].key
    title = f"{first.hull} {first.axis}: coefficients vs initial angle"
    return _per_coefficient(series, title, lambda key: (key.draft, format_draft(key.draft)), "draft")


def _plot_hulls(results: Sequence[GroupResult]) -> Figure:
    """Hulls side by side at one draft: each coefficient against the initial angle (seed 000 Fig. 7)."""
    key = results[0].key
    title = f"{key.axis} at {format_draft(key.draft)}: hulls compared"
    return _per_coefficient(results, title, lambda key: (key.hull, key.hull), None)


def _per_coefficient(
    results: Sequence[GroupResult],
    title: str,
    line_of: Callable[[GroupKey], tuple[float | str, str]],
    legend_title: str | None,
) -> Figure:
    """A panel per coefficient against the measured initial angle, one line per ``line_of(key)`` (its sort
    key and label), bars ± (95 %, fit), said in the legend's title."""
    terms = _terms(results)
    fig, axes = _figure(len(terms), title, True)
    lines = sorted({line_of(r.key) for r in results})
    for ax, term in zip(axes, terms, strict=True):
        for line in lines:
            _errorbar_series(ax, [r for r in results if line_of(r.key) == line], term, line[1])
        ax.set_xlabel("initial angle, measured (deg)")
        ax.set_title(f"{term} ({TERM_TABLE[term].unit})")
    _legend_beside(fig, axes, _titled(legend_title, interval_caption(FIT_95)))
    return fig


def _plot_b_eq(series: Sequence[GroupResult]) -> Figure:
    """B_eq(phi_a) of each group's fit over 0 ... its measured initial angle with its band ± (95 %, fit);
    colour by draft.
    Beside it B̂44 (ITTC's non-dimensional damping) where every group's hull gives beam and inertia."""

    def draw(scale: Callable[[GroupResult], float]) -> Callable[[Axes, GroupResult, str], None]:
        def band(ax: Axes, result: GroupResult, colour: str) -> None:
            grid_deg = np.linspace(0.2, _measured_angle(result), 25)
            values, std = b_eq_band(_fit(result).coefficients_, _fit(result).covariance_, grid_deg)
            values, half = values * scale(result), FIT_95.half_width(1.0) * std * scale(result)
            ax.plot(grid_deg, values, color=colour, alpha=0.8)
            ax.fill_between(grid_deg, values - half, values + half, color=colour, alpha=0.15)
            ax.plot(grid_deg[-1], values[-1], "o", color=colour)

        return band

    panels = [(draw(lambda _: 1.0), "B_eq / I (1/s)")]
    hats = {id(r): r.b44_hat_per_b_eq() for r in series}
    if all(hat is not None for hat in hats.values()):
        panels.append((draw(lambda r: float(hats[id(r)] or 0.0)), "B̂44 = B44 √(B/2g) / (ρ∇B²)"))
    return _per_draft(
        series, "equivalent linear damping", panels, "amplitude (deg)", interval_caption(FIT_95, "band")
    )


def _plot_extinction(series: Sequence[GroupResult]) -> Figure:
    """Measured decrement per half-cycle against mean amplitude, and each fit's curve (deg)."""

    def draw(ax: Axes, result: GroupResult, colour: str) -> None:
        curve = extinction_curve(result.runs, _fit(result).offsets_, _fit(result).coefficients_)
        ax.plot(np.degrees(curve.mean_amplitude), np.degrees(curve.decrement), ".", color=colour, alpha=0.6)
        ax.plot(np.degrees(curve.model_amplitude), np.degrees(curve.model_decrement), color=colour, alpha=0.8)

    return _per_draft(
        series,
        "extinction curves",
        [(draw, "decrement per half-cycle (deg)")],
        "mean amplitude of successive peaks (deg)",
    )


def _per_draft(
    series: Sequence[GroupResult],
    title: str,
    panels: Sequence[tuple[Callable[[Axes, GroupResult, str], None], str]],
    xlabel: str,
    caption: str | None = None,
) -> Figure:
    """One hull and axis, a panel per ``(draw, ylabel)``: ``draw`` each group in its draft's colour, one
    legend entry a draft, beside the panels; ``caption`` (what its intervals are) under the legend's title."""
    first = series[0].key
    fig, axes = _figure(len(panels), f"{first.hull} {first.axis}: {title}")
    drafts = sorted({r.key.draft for r in series})
    for ax, (draw, ylabel) in zip(axes, panels, strict=True):
        for result in series:
            draw(ax, result, f"C{drafts.index(result.key.draft)}")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    for i, draft in enumerate(drafts):
        axes[0].plot([], [], color=f"C{i}", label=format_draft(draft))
    _legend_beside(fig, axes, _titled("draft", caption))
    return fig


def _plot_period(results: Sequence[GroupResult]) -> Figure:
    """Natural period against draft, one line per hull: the mean over the initial angles, bars half their
    range (± (range, initial angles))."""
    fig, (ax,) = _figure(1, f"{results[0].key.axis}: natural period vs draft")
    for hull in sorted({r.key.hull for r in results}):
        drafts = sorted({r.key.draft for r in results if r.key.hull == hull})
        periods = [
            [natural_period(_fit(r).coefficients_) for r in results if (r.key.hull, r.key.draft) == (hull, d)]
            for d in drafts
        ]
        ax.errorbar(
            drafts,
            [np.mean(p) for p in periods],
            yerr=[np.ptp(p) / 2 for p in periods],  # a half-range, not a multiple of a std
            marker="o",
            capsize=3,
            label=hull,
        )
    ax.set_xlabel("draft / design draft")
    ax.set_ylabel("natural period (s)")
    _legend_beside(fig, [ax], _titled("hull", interval_caption(ANGLES_RANGE)))
    return fig


def _titled(title: str | None, caption: str | None) -> str | None:
    """A legend's title with the caption of the figure's intervals under it."""
    return "\n".join(part for part in (title, caption) if part) or None


_PLOTS: dict[str, Callable[[Sequence[GroupResult]], Figure]] = {
    "coefficients": _plot_coefficients,
    "b_eq": _plot_b_eq,
    "extinction": _plot_extinction,
    "period": _plot_period,
    "hulls": _plot_hulls,
}


def _shared_draft(results: Sequence[GroupResult]) -> float | None:
    """The draft nearest to T that two or more hulls were tested at (None when only one hull)."""
    hulls_at: dict[float, set[str]] = defaultdict(set)
    for r in results:
        hulls_at[r.key.draft].add(r.key.hull)
    shared = [d for d, hulls in hulls_at.items() if len(hulls) >= 2]
    return min(shared, key=lambda d: abs(d - 1.0)) if shared else None
