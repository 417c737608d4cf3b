"""Sensitivity of the zigzag manoeuvre to each derivative (seed 003's sensitivity analysis).

Local normalised sensitivity by perturbation (reference discrepancy-workflow.md 8.1, after Perrault et
al. 2003): each derivative is changed by +/- ``step`` (a fraction, 10 % by default), the zigzag is
re-simulated with the same switching rule, and for every manoeuvre output y

    S = (y(+) - y(-)) / (2 step y0)      (central difference, relative change per relative change)

Outputs: pitch overshoot beyond the switching angle, depth change between successive depth extremes,
the zigzag period (between plane reversals of the same sign) and the mean speed during the manoeuvre.
A derivative's overall index is the root-mean-square of its |S| over the outputs; derivatives are ranked
by it. Dominant derivatives are those whose index reaches ``dominant_threshold`` (0.1 by default: a
10 % change of the derivative moves the manoeuvre outputs by 1 % in the RMS sense).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from ..errors import InputError
from .model import StateRecord, simulate_zigzag, trim_state
from .vehicle import VISCOUS_TERMS, Vehicle

OUTPUTS: tuple[str, ...] = ("overshoot", "depth_change", "period", "speed")
OUTPUT_UNITS: dict[str, str] = {"overshoot": "rad", "depth_change": "m", "period": "s", "speed": "m/s"}


def _extremum(values: np.ndarray, t: np.ndarray, index: int) -> float:
    """Value at a sampled extremum, refined by the parabola through it and its neighbours."""
    if index <= 0 or index >= values.size - 1:
        return float(values[index])
    y0, y1, y2 = values[index - 1], values[index], values[index + 1]
    curvature = y0 - 2 * y1 + y2
    return float(y1 - 0.125 * (y2 - y0) ** 2 / curvature) if curvature != 0 else float(y1)


def manoeuvre_outputs(
    record: StateRecord, theta_switch_rad: float, theta_trim_rad: float = 0.0
) -> dict[str, float]:
    """Pitch overshoot (rad), depth change (m), period (s) and mean speed (m/s) of a zigzag record."""
    t, theta, z = record.t, record["theta"] - theta_trim_rad, record["z"]
    reversals = record.switch_times
    if reversals.size < 3:
        raise InputError("the zigzag has fewer than three plane reversals; run it longer")
    overshoots = []
    for start, end in pairwise(reversals):
        inside = np.flatnonzero((t >= start) & (t < end))
        if inside.size < 3:
            continue
        i = inside[np.argmax(np.abs(theta[inside]))]
        overshoots.append(abs(_extremum(theta, t, i)) - theta_switch_rad)
    slope = np.diff(z)
    turns = np.flatnonzero(np.sign(slope[1:]) != np.sign(slope[:-1])) + 1
    turns = turns[t[turns] > reversals[0]]
    depths = np.array([_extremum(z, t, i) for i in turns])
    if depths.size < 2 or not overshoots:
        raise InputError("the zigzag is too short to measure its depth change; run it longer")
    return {
        "overshoot": float(np.mean(overshoots)),
        "depth_change": float(np.mean(np.abs(np.diff(depths)))),
        "period": float(2.0 * np.mean(np.diff(reversals))),
        "speed": float(np.mean(record["u"][t >= reversals[0]])),
    }


@dataclass
class SensitivityResult:
    """Normalised sensitivities (derivative -> output -> S), overall indices, ranking, dominant set."""

    vehicle: str
    step: float
    delta_rad: float
    theta_rad: float
    baseline: dict[str, float]
    sensitivities: dict[str, dict[str, float]]
    index: dict[str, float]
    ranking: list[str]
    dominant: list[str]
    dominant_threshold: float

    def to_dict(self) -> dict[str, object]:
        return {
            "vehicle": self.vehicle,
            "step": self.step,
            "delta_deg": float(np.degrees(self.delta_rad)),
            "theta_deg": float(np.degrees(self.theta_rad)),
            "baseline": self.baseline,
            "output_units": OUTPUT_UNITS,
            "sensitivities": self.sensitivities,
            "index": self.index,
            "ranking": self.ranking,
            "dominant": self.dominant,
            "dominant_threshold": self.dominant_threshold,
        }


def sensitivity_analysis(
    vehicle: Vehicle,
    delta_rad: float = np.radians(15.0),
    theta_rad: float = np.radians(10.0),
    step: float = 0.10,
    dominant_threshold: float = 0.10,
    terms: Sequence[str] | None = None,
    switches: int = 8,
    progress: Callable[[int, int], None] | None = None,
) -> SensitivityResult:
    """Perturb each (non-zero) viscous derivative by +/- step, re-simulate the zigzag, rank by the index."""
    if not 0 < step < 1:
        raise InputError(f"perturbation step {step:g} must be a fraction between 0 and 1 (e.g. 0.1 for 10 %)")
    names = list(terms) if terms is not None else list(vehicle.present_terms(VISCOUS_TERMS))
    absent = [n for n in names if vehicle.coefficient(n) == 0.0]
    if absent:
        raise InputError(f"{vehicle.name} has no {absent}: a relative perturbation of zero is meaningless")

    def outputs(model: Vehicle) -> dict[str, float]:
        record = simulate_zigzag(model, delta_rad, theta_rad, switches=switches)
        return manoeuvre_outputs(record, theta_rad, float(trim_state(model)[3]))

    baseline = outputs(vehicle)
    total = 2 * len(names)
    sensitivities: dict[str, dict[str, float]] = {}
    for k, name in enumerate(names):
        value = vehicle.coefficient(name)
        up = outputs(vehicle.with_derivatives({name: value * (1 + step)}))
        down = outputs(vehicle.with_derivatives({name: value * (1 - step)}))
        sensitivities[name] = {o: (up[o] - down[o]) / (2 * step * baseline[o]) for o in OUTPUTS}
        if progress is not None:
            progress(2 * (k + 1), total)
    index = {n: float(np.sqrt(np.mean([s**2 for s in sensitivities[n].values()]))) for n in names}
    ranking = sorted(names, key=lambda n: -index[n])
    dominant = [n for n in ranking if index[n] >= dominant_threshold]
    return SensitivityResult(
        vehicle.name,
        step,
        delta_rad,
        theta_rad,
        baseline,
        sensitivities,
        index,
        ranking,
        dominant,
        dominant_threshold,
    )
