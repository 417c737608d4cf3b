"""The figures of ``tankdaq report``, as PNG bytes to embed (the report is one file): a condition's
B_eq/I with its band and Bertin's N with its bars, each interval labelled as the caller says it
(coverage and kind), and each decay with the fitted model over it (``plots.decay_fit_figure``)."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from ..ident.derived import b_eq_band
from ..ident.interval_labels import IntervalLabel
from .plots import _figure, legend_beside, report_style

#: Resolution of the embedded figures: sharp on a page, a few tens of kB each.
REPORT_DPI = 100


def png_bytes(fig: Figure, dpi: int = REPORT_DPI) -> bytes:
    """``fig`` as PNG bytes (the same bytes for the same figure: a rerun embeds the same image)."""
    out = io.BytesIO()
    fig.savefig(out, dpi=dpi, format="png", metadata={"Software": None})
    return out.getvalue()


def damping_figure(
    coefficients: Mapping[str, float],
    covariance: np.ndarray,
    amplitudes_deg: Sequence[float],
    bertin_n: Sequence[tuple[float, float]],
    interval: IntervalLabel,
    title: str,
) -> Figure:
    """B_eq/I against amplitude with its band from the fit's covariance (delta method), the table's
    amplitudes marked, and Bertin's N (value, std) at those amplitudes with bars; band and bars are
    ``interval``'s half-width of the standard deviation, and the legend says which."""
    with report_style():
        fig, (top, bottom) = _figure(2, sharex=True)
        grid = np.linspace(min(0.2, min(amplitudes_deg)), max(amplitudes_deg), 60)
        values, std = b_eq_band(coefficients, covariance, grid)
        top.plot(grid, values, color="C0", label="B_eq/I (fit)")
        half = interval.half_width(1.0)
        top.fill_between(grid, values - half * std, values + half * std, color="C0", alpha=0.25,
                         label=f"B_eq/I {interval.text}")  # fmt: skip
        at, _ = b_eq_band(coefficients, covariance, amplitudes_deg)
        top.plot(amplitudes_deg, at, "o", color="C0", label="table amplitudes")
        top.set_ylabel("B_eq / I (1/s)")
        legend_beside(top)
        n = np.array([value for value, _ in bertin_n])
        n_std = np.array([s for _, s in bertin_n])
        bottom.errorbar(amplitudes_deg, n, yerr=half * n_std, marker="o", capsize=3, color="C1",
                        label=f"Bertin N {interval.text}")  # fmt: skip
        bottom.set_ylabel("Bertin N (1/deg)")
        bottom.set_xlabel("amplitude (deg)")
        legend_beside(bottom)
        top.set_title(title)
    return fig
