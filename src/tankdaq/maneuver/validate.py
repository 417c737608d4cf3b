"""Re-simulate a measured manoeuvre with an identified model and score the match (seed 003's last step).

The model is driven open-loop by the measured stern-plane angle from the measured initial state, so
the comparison tests the model rather than the switching logic. Fit measure per state:
R^2 = 1 - sum (y - y_sim)^2 / sum (y - mean y)^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .model import STATE_COLUMNS, StateRecord, replay
from .vehicle import Vehicle

#: States scored (x is dominated by the forward run and says little about the model).
SCORED_STATES: tuple[str, ...] = ("u", "w", "q", "theta", "z")
#: Seconds fitted by a straight line for the initial state: sensor noise in it would persist (pitch is
#: only weakly restored) and show up as a depth drift.
INITIAL_FIT_S = 1.0


@dataclass
class ValidationResult:
    """A re-simulation of a record and its R^2 per state."""

    label: str
    simulated: StateRecord
    r2: dict[str, float]


def r_squared(measured: np.ndarray, simulated: np.ndarray) -> float:
    spread = float(np.sum((measured - measured.mean()) ** 2))
    return 1.0 - float(np.sum((measured - simulated) ** 2)) / spread if spread > 0 else float("nan")


def resimulate(record: StateRecord, model: Vehicle, label: str) -> ValidationResult:
    """Drive ``model`` with the record's stern-plane angle and compare every scored state."""
    n_start = max(2, round(INITIAL_FIT_S * record.rate_hz))
    t = record.t[:n_start] - record.t[0]
    state0 = np.array([np.polyfit(t, record[c][:n_start], 1)[1] for c in STATE_COLUMNS])
    simulated = replay(model, record.t, record["delta_s"], state0)
    r2 = {c: r_squared(record[c], simulated[c]) for c in SCORED_STATES}
    return ValidationResult(label, simulated, r2)


def plot_validation(record: StateRecord, results: list[ValidationResult], path: str | Path) -> Path:
    """PNG of measured vs re-simulated pitch, pitch rate, heave velocity, depth and plane angle."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise InputError(f"{path}: the plot is written as PNG; give a file name ending in .png")
    panels = (("theta", "pitch [deg]", True), ("q", "pitch rate [deg/s]", True),
              ("w", "heave velocity [m/s]", False), ("z", "depth [m]", False),
              ("delta_s", "stern plane [deg]", True))
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 11), sharex=True)
    for ax, (column, label, in_degrees) in zip(axes, panels, strict=True):
        scale = np.degrees(1.0) if in_degrees else 1.0
        ax.plot(record.t, record[column] * scale, color="0.3", lw=1.0, label="measured")
        if column != "delta_s":
            for result in results:
                ax.plot(result.simulated.t, result.simulated[column] * scale, lw=1.2,
                        label=f"{result.label} (R² {result.r2[column]:.3f})")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{record.meta.get('vehicle', 'vehicle')}: re-simulated manoeuvre")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
