"""The 2007-era MTi-G's output settings, and a sample's values in the form its messages carry.

A Mark III MTi-G knows no SetOutputConfiguration: what it sends follows from OutputMode,
OutputSettings and Period (reference §4). The codec is ``tankdaq.xsens.legacy``; this module
holds the settings the driver asks for and the simulator plays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ProtocolError
from ..xsens.legacy import (
    DISABLE_MAG,
    MODE_CALIBRATED,
    MODE_ORIENTATION,
    MODE_STATUS,
    LegacyLayout,
    legacy_layout,
)
from ..xsens.orientation import quaternion, rotation_matrix

#: SetPeriod counts in 1/115200 s; 1152 is 100 Hz.
PERIOD_CLOCK_HZ = 115200
TIMESTAMP_COUNTER = 0x0001
ORIENTATION_EULER = 0x0004
#: Blocks the simulated legacy device can fill (others: it answers "invalid parameter").
SIMULATED_BLOCKS = frozenset(
    {"Temperature", "Acceleration", "RateOfTurn", "MagneticField", "Quaternion", "EulerAngles",
     "RotationMatrix", "StatusByte", "PacketCounter"}
)  # fmt: skip


@dataclass(frozen=True)
class LegacyOutput:
    """OutputMode, OutputSettings and Period of a Mark III MTi-G."""

    mode: int
    settings: int
    period: int

    @classmethod
    def default(cls) -> LegacyOutput:
        """Factory default (MT0100P p. 25): quaternion and sample counter at 100 Hz."""
        return cls(MODE_ORIENTATION, TIMESTAMP_COUNTER, 1152)

    @classmethod
    def for_decay(cls, rate_hz: float) -> LegacyOutput:
        """Calibrated acceleration and rate (no magnetometer), Euler angles, status, sample counter."""
        return cls(
            MODE_CALIBRATED | MODE_ORIENTATION | MODE_STATUS,
            TIMESTAMP_COUNTER | ORIENTATION_EULER | DISABLE_MAG,
            round(PERIOD_CLOCK_HZ / rate_hz),
        )

    @property
    def rate_hz(self) -> float:
        return PERIOD_CLOCK_HZ / self.period

    @property
    def layout(self) -> LegacyLayout:
        return legacy_layout(self.mode, self.settings)

    def check_simulated(self) -> None:
        """ProtocolError when the simulator cannot produce these settings."""
        if self.period <= 0:
            raise ProtocolError("legacy period must be positive")
        unknown = [b.name for b in self.layout.blocks if b.name not in SIMULATED_BLOCKS]
        if unknown:
            raise ProtocolError(f"the simulated legacy MTi-G cannot send {', '.join(unknown)}")


def sample_values(sample: np.void) -> dict[str, object]:
    """A ``SAMPLE_DTYPE`` sample as legacy block values (device units: Euler in degrees)."""
    roll, pitch, yaw = (float(sample[f]) for f in ("roll", "pitch", "yaw"))
    return {
        "Temperature": 21.5,
        "Acceleration": tuple(float(sample[f]) for f in ("ax", "ay", "az")),
        "RateOfTurn": tuple(float(sample[f]) for f in ("p", "q", "r")),
        "MagneticField": (1.0, 0.0, 0.0),
        "EulerAngles": (math.degrees(roll), math.degrees(pitch), math.degrees(yaw)),
        "Quaternion": tuple(quaternion(roll, pitch, yaw).tolist()),
        "RotationMatrix": tuple(rotation_matrix(roll, pitch, yaw).tolist()),
        "StatusByte": int(sample["status"]) & 0xFF,
        "PacketCounter": int(sample["counter"]) & 0xFFFF,
    }
