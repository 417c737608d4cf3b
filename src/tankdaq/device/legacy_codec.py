"""Adapter: the legacy MTData (0x32) layout for the subset a decay test uses.

``tankdaq.xsens.legacy`` (the protocol room's full codec) had not landed when the device room
needed it, so this small module covers what the simulator sends and the driver reads:
temperature, calibrated data (acc/gyr/mag, each part can be disabled), orientation
(quaternion, Euler, matrix), status and the sample counter, all float32 (reference §4).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from ..errors import ProtocolError

MODE_TEMPERATURE = 0x0001
MODE_CALIBRATED = 0x0002
MODE_ORIENTATION = 0x0004
MODE_STATUS = 0x0800
SUPPORTED_MODE_BITS = MODE_TEMPERATURE | MODE_CALIBRATED | MODE_ORIENTATION | MODE_STATUS

TIMESTAMP_MASK = 0x0003
TIMESTAMP_COUNTER = 0x0001
ORIENTATION_MASK = 0x000C
ORIENTATION_QUATERNION, ORIENTATION_EULER, ORIENTATION_MATRIX = 0x0, 0x4, 0x8
DISABLE_ACC, DISABLE_GYR, DISABLE_MAG = 0x0010, 0x0020, 0x0040
FORMAT_MASK = 0x0300

#: SetPeriod counts in 1/115200 s; 1152 is 100 Hz.
PERIOD_CLOCK_HZ = 115200
ORIENTATION_SIZES = {ORIENTATION_QUATERNION: 4, ORIENTATION_EULER: 3, ORIENTATION_MATRIX: 9}


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
        """Calibrated acc + gyr, Euler angles, status and sample counter at ``rate_hz``."""
        return cls(
            MODE_CALIBRATED | MODE_ORIENTATION | MODE_STATUS,
            TIMESTAMP_COUNTER | ORIENTATION_EULER | DISABLE_MAG,
            round(PERIOD_CLOCK_HZ / rate_hz),
        )

    @property
    def rate_hz(self) -> float:
        return PERIOD_CLOCK_HZ / self.period

    def check(self) -> None:
        """ProtocolError for settings this codec does not cover."""
        if self.mode & ~SUPPORTED_MODE_BITS:
            raise ProtocolError(f"legacy output mode 0x{self.mode:04X} has parts tankdaq does not decode")
        if self.settings & FORMAT_MASK:
            raise ProtocolError(
                "legacy fixed-point output is not supported: use float32 (settings bits 9-8 = 0)"
            )
        if self.period <= 0:
            raise ProtocolError("legacy period must be positive")

    def blocks(self) -> list[tuple[str, int]]:
        """(name, float count) of each block in wire order; status and counter are integers."""
        out: list[tuple[str, int]] = []
        if self.mode & MODE_TEMPERATURE:
            out.append(("temperature", 1))
        if self.mode & MODE_CALIBRATED:
            for name, bit in (("acc", DISABLE_ACC), ("gyr", DISABLE_GYR), ("mag", DISABLE_MAG)):
                if not self.settings & bit:
                    out.append((name, 3))
        if self.mode & MODE_ORIENTATION:
            kind = self.settings & ORIENTATION_MASK
            out.append(({0x0: "quaternion", 0x4: "euler", 0x8: "matrix"}[kind], ORIENTATION_SIZES[kind]))
        return out

    @property
    def has_status(self) -> bool:
        return bool(self.mode & MODE_STATUS)

    @property
    def has_counter(self) -> bool:
        return self.settings & TIMESTAMP_MASK == TIMESTAMP_COUNTER

    @property
    def size(self) -> int:
        return 4 * sum(n for _, n in self.blocks()) + self.has_status + 2 * self.has_counter


def _cos_sin(*angles: float) -> tuple[float, ...]:
    """cos a1, sin a1, cos a2, sin a2, ..."""
    return tuple(f(a) for a in angles for f in (math.cos, math.sin))


def _orientation_values(kind: str, roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """Orientation block values from ZYX Euler angles (rad)."""
    if kind == "euler":
        return (math.degrees(roll), math.degrees(pitch), math.degrees(yaw))
    if kind == "quaternion":
        hr, gr, hp, gp, hy, gy = _cos_sin(roll / 2, pitch / 2, yaw / 2)
        return (hr * hp * hy + gr * gp * gy, gr * hp * hy - hr * gp * gy, hr * gp * hy + gr * hp * gy,
                hr * hp * gy - gr * gp * hy)  # fmt: skip
    cr, sr, cp, sp, cy, sy = _cos_sin(roll, pitch, yaw)
    return (cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy,
            cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy,
            -sp, sr * cp, cr * cp)  # fmt: skip


def encode(output: LegacyOutput, sample: np.void) -> bytes:
    """MTData payload of one ``SAMPLE_DTYPE`` sample (magnetic field reads as a fixed unit north)."""
    parts: list[bytes] = []
    for name, count in output.blocks():
        if name == "temperature":
            values: tuple[float, ...] = (21.5,)
        elif name == "acc":
            values = tuple(float(sample[f]) for f in ("ax", "ay", "az"))
        elif name == "gyr":
            values = tuple(float(sample[f]) for f in ("p", "q", "r"))
        elif name == "mag":
            values = (1.0, 0.0, 0.0)
        else:
            values = _orientation_values(name, *(float(sample[f]) for f in ("roll", "pitch", "yaw")))
        parts.append(struct.pack(f">{count}f", *values))
    if output.has_status:
        parts.append(bytes((int(sample["status"]) & 0xFF,)))
    if output.has_counter:
        parts.append(struct.pack(">H", int(sample["counter"]) & 0xFFFF))
    return b"".join(parts)


def decode(output: LegacyOutput, payload: bytes) -> dict[str, object]:
    """Values of one MTData payload (device units: Euler in degrees), keyed by block name."""
    if len(payload) != output.size:
        raise ProtocolError(
            f"MTData of {len(payload)} bytes does not fit the configured legacy layout ({output.size} bytes)"
        )
    out: dict[str, object] = {}
    offset = 0
    for name, count in output.blocks():
        out[name] = struct.unpack_from(f">{count}f", payload, offset)
        offset += 4 * count
    if output.has_status:
        out["status"] = payload[offset]
        offset += 1
    if output.has_counter:
        out["counter"] = struct.unpack_from(">H", payload, offset)[0]
    return out
