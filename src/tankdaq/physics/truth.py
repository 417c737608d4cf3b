"""What a simulated decay test really did: the true motion on the sample grid and the truth of each run.

Apart from the scripted scenario that makes it and the sensor model that measures it, so the
simulator, the tests and the API can read the truth without either.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from enum import StrEnum

import numpy as np

from .decay import TERMS

#: SampleTimeFine ticks per second, and the wrap of the 10/100-series (one day of ticks).
TICKS_PER_S = 10_000
TICK_MODULUS = 864_000_000


class RunKind(StrEnum):
    """How a simulated run went: released into a decay, or put back by hand without a release."""

    RELEASE = "release"
    PUT_BACK = "put_back"


@dataclass(frozen=True)
class RunTruth:
    """What really happened in one run (angles in rad; times on the device clock)."""

    run: int
    kind: RunKind
    axis: str
    tilt_start_s: float
    release_s: float | None = None
    release_ticks: int | None = None  # SampleTimeFine at release, wrapped like the device's counter
    release_index: int | None = None  # the first sample at or after the release: the first free sample
    angle0_rad: float | None = None
    rate0_rad_s: float | None = None
    end_s: float = 0.0
    coefficients: dict[str, float] = field(default_factory=dict)
    pushed_again_s: float | None = None  # the hand pushed the model again mid-decay (not a free decay)

    @property
    def terms(self) -> list[str]:
        return [k for k in TERMS if self.coefficients.get(k, 0.0) != 0.0]

    def to_json(self) -> dict[str, object]:
        """Plain JSON: SI values, plus degrees for people."""
        out: dict[str, object] = asdict(self) | {"kind": self.kind.value}
        out["terms"] = self.terms
        if self.angle0_rad is not None:
            out["angle0_deg"] = math.degrees(self.angle0_rad)
        return out


@dataclass
class ScenarioTrace:
    """True motion on the sample grid, and the truth of every run."""

    rate_hz: float
    axis: str
    start_ticks: int
    t: np.ndarray  # s since the scenario start (device clock)
    angle: np.ndarray  # rad, sensed axis
    rate: np.ndarray  # rad/s
    acc: np.ndarray  # rad/s^2
    other_angle: np.ndarray  # rad, the other of roll/pitch
    other_rate: np.ndarray
    heave_m: np.ndarray
    heave_acc_m_s2: np.ndarray
    runs: list[RunTruth]

    @property
    def ticks(self) -> np.ndarray:
        """Unwrapped SampleTimeFine of every sample."""
        return self.start_ticks + np.round(self.t * TICKS_PER_S).astype(np.int64)

    def __len__(self) -> int:
        return int(self.t.size)


def still_trace(rate_hz: float, axis: str, start_ticks: int, start_index: int, n: int) -> ScenarioTrace:
    """Still water on the sample grid from sample ``start_index`` on (after the scripted runs)."""
    t = (start_index + np.arange(n)) / rate_hz
    zeros = np.zeros(n)
    return ScenarioTrace(
        rate_hz, axis, start_ticks, t, zeros, zeros, zeros, zeros + math.radians(0.3), zeros, zeros, zeros, []
    )
