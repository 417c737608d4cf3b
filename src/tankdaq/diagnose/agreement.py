"""How a simulation and the measurement agree, cycle by cycle: B_eq and the period at each amplitude.

``DampingPoint`` holds B_eq of the measurement, the simulation and the corrected model at one amplitude
with their intervals; ``period_check`` sets each measured cycle's period against the simulation's at
that cycle's amplitude (describing function, ITTC eq. 14). ``differs_sentence`` says what differs in
the damping without naming a cause (the comparison says it when an effect lacks its own evidence).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..ident.derived import equivalent_frequency
from .residuals import CycleTrend

#: Periods agree within this fraction; damping disagrees when its 95 % intervals part by more than 10 %.
PERIOD_TOLERANCE, DAMPING_TOLERANCE = 0.005, 0.10


@dataclass
class DampingPoint:
    """B_eq (1/s) of the measurement, the simulation and the corrected model at one amplitude, +-1.96 std."""

    amplitude_deg: float
    measured: tuple[float, float]  # value, std
    simulation: tuple[float, float]
    corrected: tuple[float, float]

    @property
    def ratio(self) -> float:
        return self.simulation[0] / self.measured[0]

    @property
    def ratio_ci95(self) -> tuple[float, float]:
        (bm, sm), (bs, ss) = self.measured, self.simulation
        rel = math.hypot(sm / bm, ss / bs) if bm and bs else math.inf
        return self.ratio * (1 - 1.96 * rel), self.ratio * (1 + 1.96 * rel)

    @property
    def disagrees(self) -> bool:
        (bm, sm), (bs, ss) = self.measured, self.simulation
        return abs(bs - bm) > max(1.96 * math.hypot(sm, ss), DAMPING_TOLERANCE * abs(bm))


@dataclass
class PeriodPoint:
    """The undamped period (s) at one amplitude from each equation (describing function, ITTC eq. 14)."""

    amplitude_deg: float
    measured: float
    simulation: float
    corrected: float

    @property
    def simulation_error(self) -> float:
        return self.simulation / self.measured - 1.0


@dataclass
class PeriodCheck:
    """Measured cycle periods against the simulation's period at each cycle's amplitude (model-free side)."""

    error: float  # median of T_simulation / T_measured - 1 over the measured cycles
    ci95: float  # half-width of its 95 % interval (median's standard error, 1.2533 s / sqrt(n))
    cycles: int
    measured_s: float  # median measured cycle period
    simulation_s: float  # the simulation's period at the measured cycles' median amplitude

    @property
    def disagrees(self) -> bool:
        return self.cycles > 0 and abs(self.error) > max(PERIOD_TOLERANCE, self.ci95)


def period_check(measured: CycleTrend, simulation: Mapping[str, float]) -> PeriodCheck:
    """Each measured cycle's period against the simulation equation's at the cycle's amplitude
    (describing function; damping moves a period by ~zeta^2/2, negligible here)."""
    if measured.period_s.size == 0:
        return PeriodCheck(math.nan, math.nan, 0, math.nan, math.nan)
    sim = np.array([2 * math.pi / equivalent_frequency(simulation, a) for a in measured.amplitude_rad])
    ratio = sim / measured.period_s
    spread = float(np.std(ratio, ddof=1)) if ratio.size > 1 else math.inf
    median_amplitude = float(np.median(measured.amplitude_rad))
    return PeriodCheck(
        float(np.median(ratio)) - 1.0,
        1.96 * 1.2533 * spread / math.sqrt(ratio.size),
        int(ratio.size),
        float(np.median(measured.period_s)),
        2 * math.pi / equivalent_frequency(simulation, median_amplitude),
    )


def differs_sentence(points: list[DampingPoint], what: str = "simulation") -> str:
    """What differs in the damping, from the smallest to the largest tested amplitude, with no cause."""
    small, large = points[0], points[-1]
    made = "predicted" if what == "prediction" else "simulated"
    shares = (
        f"the {what} has {100 * small.ratio:.0f} % of the measured damping at {small.amplitude_deg:.2g} deg "
        f"and {100 * large.ratio:.0f} % at {large.amplitude_deg:.3g} deg"
    )
    if small.ratio < (1 - DAMPING_TOLERANCE) * large.ratio:
        return f"{shares}: more damping at small amplitude than {made}"
    if large.ratio < (1 - DAMPING_TOLERANCE) * small.ratio:
        return f"{shares}: more damping at large amplitude than {made}"
    return f"{shares}: off by about the same share at every amplitude"
