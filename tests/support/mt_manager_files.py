"""MT Manager text exports of a known decay, written as each MT Manager generation writes them.

The decay is ``held_tilt``'s (coefficients ``TRUTH``); the device also pitches a little and heads
somewhere, so a roll read from the wrong quaternion component or matrix entry shows. Each writer puts
the roll into the representation asked for (Euler ``Roll``/``Euler_X``, quaternion, matrix), the time into
SampleTimeFine (starting ``start_tick``, wrapped at ``modulus``) or only PacketCounter (zero-padded,
wrapped at 2**16), with empty or ``NaN`` fields where an output was not logged.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from support.held_tilt import RATE_HZ, held_tilt
from tankdaq.xsens.orientation import quaternion, rotation_matrix

PITCH_RAD = math.radians(1.5)
YAW_RAD = math.radians(-116.0)
HEADERS = {
    "4.x": [
        "// Start Time: Unknown",
        "// Update Rate: 100.0Hz",
        "// Filter Profile: human (46.1)",
        "// Option Flags: AHS Disabled ICC Disabled ",
        "// Firmware Version: 4.0.2",
    ],
    "2019.2": [
        "// General information: ",
        "//  MT Manager version: 2019.2.1 ",
        "//  XDA version: 2019.2.1 build 1234 rev 5678",
        "// Device information: ",
        "//  DeviceId: 03781234",
        "//  ProductCode: MTi-G-710-2A8G4",
        "//  Firmware Version: 1.8.2",
        "// Device settings: ",
        "//  Filter Profile: General(11.5)",
        "// Coordinate system: ENU",
    ],
    "2022.2": [
        "// General information: ",
        "//  MT Manager version: 2022.2.0 ",
        "//  XDA version: 2022.2.0 build 7381 rev 124627 built on 2023-07-19",
        "// Device information: ",
        "//  DeviceId: 00B42D4B",
        "//  ProductCode: MTi-680G",
        "//  Firmware Version: 1.12.0",
        "//  Hardware Version: 1.1.0",
        "// Device settings: ",
        "//  Filter Profile: General(11.1)",
        "//  Option Flags: Orientation Smoother Disabled, AHS Disabled, ICC Disabled",
        "// Coordinate system: ENU",
    ],
}
EULER_NAMES = {"Roll": ["Roll", "Pitch", "Yaw"], "Euler": ["Euler_X", "Euler_Y", "Euler_Z"]}
QUATERNION_NAMES = [f"Quat_q{k}" for k in range(4)]
MATRIX_NAMES = [f"Mat[{i}][{j}]" for j in (1, 2, 3) for i in (1, 2, 3)]  # MT Manager's order: by column


def orientation(kind: str, decay: np.ndarray, axis: str = "roll") -> tuple[list[str], np.ndarray]:
    """The orientation columns of ``kind`` (Roll, Euler, Quat, Mat) with the decay on ``axis`` and the
    other angles held: names and values (degrees for Euler, as MT Manager writes them)."""
    held, yaw = np.full_like(decay, PITCH_RAD), np.full_like(decay, YAW_RAD)
    roll, pitch = (decay, held) if axis == "roll" else (held, decay)
    if kind in EULER_NAMES:
        return EULER_NAMES[kind], np.degrees(np.stack([roll, pitch, yaw], axis=-1))
    if kind == "Quat":
        return QUATERNION_NAMES, quaternion(roll, pitch, yaw)
    return MATRIX_NAMES, rotation_matrix(roll, pitch, yaw)


def write_export(
    path: Path,
    generation: str = "2022.2",
    kind: str = "Roll",
    delimiter: str = "\t",
    sample_time: bool = True,
    start_tick: int = 4_562_336,
    modulus: int = 864_000_000,
    missing: str = "",
    crlf: bool = True,
    counter_start: int = 65_000,
    axis: str = "roll",
    decimal_comma: bool = False,
) -> Path:
    """The decay as MT Manager ``generation`` exports it (``missing``: what an output not logged
    shows, empty or ``NaN``; ``sample_time`` False: SampleTimeFine not logged; ``decimal_comma``: a
    European locale's numbers, behind a byte-order mark and a blank line)."""
    t, roll, _ = held_tilt()
    names, values = orientation(kind, roll, axis)
    header = ["PacketCounter", "SampleTimeFine", "Year", "Month", "Acc_X", "Acc_Y", "Acc_Z", *names]
    ticks = (start_tick + np.round(t * 10_000).astype(np.int64)) % modulus
    counter = (counter_start + np.arange(t.size)) % 65_536
    rows = []
    for i in range(t.size):
        cells = [f"{counter[i]:05d}", str(ticks[i]) if sample_time else missing, missing, missing]
        cells += ["0.012345", "-0.170000", "9.810000"] + [f"{v:.6f}" for v in values[i]]
        rows.append(delimiter.join(cells).replace(".", ",") if decimal_comma else delimiter.join(cells))
    end = "\r\n" if crlf else "\n"
    block = [*HEADERS[generation], *([""] if decimal_comma else [])]
    text = ("\ufeff" if decimal_comma else "") + end.join([*block, delimiter.join(header), *rows]) + end
    path.write_bytes(text.encode())
    return path


__all__ = ["RATE_HZ", "write_export"]
