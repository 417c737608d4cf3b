"""The AUV validation figure: a measured diving-plane manoeuvre against its re-simulations.

Built like every report figure (``viz.plots``: ``Figure`` on the Agg canvas, ``report_style``), so
``tankdaq auv validate --plot`` needs no pyplot; the scores come from ``auv.validate``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..auv.model import StateRecord
from ..auv.validate import ValidationResult
from .plots import legend_beside, report_style

#: Panels top to bottom: state column, axis label, drawn in degrees.
PANELS: tuple[tuple[str, str, bool], ...] = (
    ("theta", "pitch (deg)", True),
    ("q", "pitch rate (deg/s)", True),
    ("w", "heave velocity (m/s)", False),
    ("z", "depth (m)", False),
    ("delta_s", "stern plane (deg)", True),
)


def validation_figure(record: StateRecord, results: Sequence[ValidationResult]) -> Figure:
    """Measured pitch, pitch rate, heave velocity, depth and plane angle, with each re-simulation over
    them (its R^2 in the legend for the scored states)."""
    with report_style():
        fig = Figure(figsize=(11.0, 11.0), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(len(PANELS), 1, sharex=True, squeeze=False)[:, 0]
        for ax, (column, label, in_degrees) in zip(axes, PANELS, strict=True):
            scale = np.degrees(1.0) if in_degrees else 1.0
            # grey: the colour cycle's blue is the first re-simulation's
            ax.plot(record.t, record[column] * scale, color="0.3", linewidth=1.0, label="measured")
            for result in results:
                score = f" (R² {result.r2[column]:.3f})" if column in result.r2 else ""
                simulated = result.simulated
                ax.plot(simulated.t, simulated[column] * scale, label=f"{result.label}{score}")
            ax.set_ylabel(label)
            legend_beside(ax, fontsize=7)  # each panel's own scores, right of its data
        axes[-1].set_xlabel("time (s)")
        fig.suptitle(f"{record.meta.get('vehicle', 'vehicle')}: re-simulated manoeuvre")
    return fig
