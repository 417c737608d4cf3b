"""Re-simulate a measured manoeuvre with an identified model and score the match (seed 003's last step).

Two ways to re-simulate:

- ``zigzag``: run the manoeuvre again with the model, same rule and angles (from the record's metadata),
  from the model's own trim. The plane follows the model's pitch, as it did the vehicle's, so small
  errors in the static moment balance do not accumulate: this is the prediction of the manoeuvre.
- ``replay``: drive the model open-loop with the measured plane angle from the measured initial state.
  Works for any record, but a vehicle with an unstable or barely damped slow mode (REMUS 100 in this
  model) drifts away from any small error in the initial state or the trim: use it for NPS-like
  vehicles or short records.

Fit measure per state: R^2 = 1 - sum (y - y_sim)^2 / sum (y - mean y)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .model import STATE_COLUMNS, StateRecord, replay, simulate_zigzag
from .vehicle import Vehicle

MODES: tuple[str, ...] = ("zigzag", "replay")

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


def default_mode(record: StateRecord) -> str:
    """zigzag when the record says it is one (with its angles), else replay."""
    meta = record.meta
    return (
        "zigzag"
        if meta.get("manoeuvre") == "zigzag" and "delta_deg" in meta and "theta_deg" in meta
        else "replay"
    )


def _replay(record: StateRecord, model: Vehicle) -> StateRecord:
    n_start = max(2, round(INITIAL_FIT_S * record.rate_hz))
    t = record.t[:n_start] - record.t[0]
    state0 = np.array([np.polyfit(t, record[c][:n_start], 1)[1] for c in STATE_COLUMNS])
    return replay(model, record.t, record["delta_s"], state0)


def _rerun_zigzag(record: StateRecord, model: Vehicle) -> StateRecord:
    meta = record.meta
    try:
        delta_rad, theta_rad = np.radians(float(meta["delta_deg"])), np.radians(float(meta["theta_deg"]))
        approach_s = float(meta.get("approach_s", 5.0))
        switches = int(meta.get("switches", 8))
    except (KeyError, ValueError):
        raise InputError(
            "the record does not say which zigzag it is (delta_deg, theta_deg metadata); "
            "re-simulate it by replay instead"
        ) from None
    # twice the reversals, so the re-run covers the record even if the model's period is much shorter
    rerun = simulate_zigzag(
        model, delta_rad, theta_rad, switches=2 * switches + 2, rate_hz=record.rate_hz, approach_s=approach_s
    )
    t = record.t - record.t[0]
    if rerun.t[-1] < t[-1]:
        raise InputError(f"{model.name}'s zigzag is much slower than the record's; it cannot be compared")
    states = {c: np.interp(t, rerun.t, rerun[c]) for c in STATE_COLUMNS}
    return StateRecord(t=record.t.copy(), states=states, meta=rerun.meta)


def resimulate(record: StateRecord, model: Vehicle, label: str, mode: str | None = None) -> ValidationResult:
    """Re-simulate ``record`` with ``model`` (``mode``: zigzag, replay, None = default_mode) and score it."""
    mode = mode or default_mode(record)
    if mode not in MODES:
        raise InputError(f"re-simulation mode {mode!r} unknown; use {' or '.join(MODES)}")
    simulated = _rerun_zigzag(record, model) if mode == "zigzag" else _replay(record, model)
    r2 = {c: r_squared(record[c], simulated[c]) for c in SCORED_STATES}
    return ValidationResult(label, simulated, r2)
