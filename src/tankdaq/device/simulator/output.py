"""What the simulated device sends: its output configuration, and samples encoded into messages.

An MTi-G-710 sends MTData2 as SetOutputConfiguration asked (rates rounded down to a divisor of
400 Hz, frames forced to ENU); the 2007-era MTi-G sends legacy MTData from OutputMode,
OutputSettings and Period. ``Output`` holds whichever of the two is in force and turns sample
rows into the frames that carry them: MTData2 a block at a time (``frames``), legacy MTData through
the ``tankdaq.xsens`` encoders.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...physics.truth import TICK_MODULUS
from ...xsens.constants import MID
from ...xsens.control import MAX_FREQUENCY, PER_MESSAGE_OUTPUTS
from ...xsens.frame import build_frame
from ...xsens.legacy import encode_mtdata
from ...xsens.mtdata2 import FRAME_MASK, SPEC_BY_BASE, TYPE_MASK, make_xdi
from ..legacy_output import LegacyOutput, sample_values
from .frames import mtdata2_frames

#: Rates an MTi-G-710 can output: divisors of 400 Hz (the echo rounds a request down to one).
DEVICE_RATES_HZ = (1, 2, 4, 5, 8, 10, 16, 20, 25, 40, 50, 80, 100, 200, 400)
MAX_RATE_HZ = 400
#: Outputs the simulator can produce (a request for others is dropped from the echoed configuration).
SUPPORTED_OUTPUTS = frozenset(
    {"PacketCounter", "SampleTimeFine", "SampleTimeCoarse", "EulerAngles", "Quaternion", "RotationMatrix",
     "RateOfTurn", "Acceleration", "StatusWord", "StatusByte"}
)  # fmt: skip


@dataclass
class OutputItem:
    """One configured output: identifier and the frequency the device will really use (Hz)."""

    xdi: int
    hz: int  # MAX_FREQUENCY for outputs that ride along with every message

    @property
    def name(self) -> str:
        return SPEC_BY_BASE[self.xdi & TYPE_MASK].name


def effective_configuration(requested: list[tuple[int, int]]) -> list[OutputItem]:
    """What the device makes of a requested configuration: unsupported outputs dropped, frames
    forced to ENU, rates rounded down to a divisor of 400 Hz, per-message outputs at 0xFFFF."""
    items: list[OutputItem] = []
    for xdi, hz in requested:
        spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
        if spec is None or spec.name not in SUPPORTED_OUTPUTS:
            continue
        if spec.name in PER_MESSAGE_OUTPUTS:
            items.append(OutputItem(xdi, MAX_FREQUENCY))
            continue
        rate = MAX_RATE_HZ if hz in (0, MAX_FREQUENCY) else max(r for r in DEVICE_RATES_HZ if r <= max(hz, 1))
        items.append(OutputItem(xdi & ~FRAME_MASK, rate))
    return items


def default_configuration(rate_hz: int = 100, without: frozenset[str] = frozenset()) -> list[OutputItem]:
    """MTi-G-710 factory-like default: counter, time, quaternion, status at 100 Hz (``without`` the
    outputs the device does not have: an IMU-class device sends no quaternion)."""
    names = [n for n in ("PacketCounter", "SampleTimeFine", "Quaternion", "StatusWord") if n not in without]
    return effective_configuration([(make_xdi(n), rate_hz) for n in names])


@dataclass
class Output:
    """The output settings in force: MTData2 items, or (``legacy``) the Mark III's legacy settings."""

    legacy: bool = False
    items: list[OutputItem] = field(default_factory=default_configuration)
    legacy_mode: LegacyOutput = field(default_factory=LegacyOutput.default)
    #: where SampleTimeFine wraps: the device family's modulus (one day on an MTi-G-710, 2**32 on a 600)
    clock_modulus: int = TICK_MODULUS
    #: outputs the device does not have (it refuses them): never in its defaults
    lacking: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        self.items = [item for item in self.items if item.name not in self.lacking]

    def restore_defaults(self) -> None:
        self.items = default_configuration(without=self.lacking)
        self.legacy_mode = LegacyOutput.default()

    @property
    def entries(self) -> list[tuple[int, int]]:
        """(xdi, Hz) pairs, as an OutputConfiguration ack carries them."""
        return [(item.xdi, item.hz) for item in self.items]

    @property
    def rate_hz(self) -> float:
        """Messages per second: the fastest configured output (legacy: the period's rate)."""
        if self.legacy:
            return self.legacy_mode.rate_hz
        rates = [item.hz for item in self.items if item.hz != MAX_FREQUENCY]
        return float(max(rates) if rates else 100)

    def encode(self, block: np.ndarray, indices: np.ndarray) -> list[bytes]:
        """One frame per sample row (``indices`` on the device's sample grid pick the slower outputs)."""
        if self.legacy:
            mode, settings = self.legacy_mode.mode, self.legacy_mode.settings
            return [build_frame(MID.MTDATA, encode_mtdata(sample_values(s), mode, settings)) for s in block]
        rate = self.rate_hz
        present = np.ones((block.size, len(self.items)), dtype=bool)
        for j, item in enumerate(self.items):
            every = 1 if item.hz == MAX_FREQUENCY else max(1, round(rate / item.hz))  # frames
            if every > 1:
                present[:, j] = indices % every == 0
        return mtdata2_frames(block, present, [item.xdi for item in self.items], self.clock_modulus)
