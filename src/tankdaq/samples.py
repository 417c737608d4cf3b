"""The sample: one decoded inertial measurement in SI units, as a numpy record.

The device driver turns MTData2 messages into arrays of ``SAMPLE_DTYPE``; every
later stage (release detection, recording, identification, viewing) eats these
arrays. Angles are in rad and rates in rad/s inside tankdaq; the Xsens wire
format carries Euler angles in degrees, so the conversion happens once, here.
"""

from __future__ import annotations

import numpy as np

SAMPLE_DTYPE = np.dtype(
    [
        ("t", "f8"),  # device time, s: unwrapped SampleTimeFine / 10 kHz
        ("ticks", "i8"),  # unwrapped SampleTimeFine, 0.1 ms ticks
        ("host_t", "f8"),  # host wall-clock time at arrival, s since epoch (alignment only)
        ("counter", "u2"),  # PacketCounter (wraps at 65536)
        ("roll", "f8"),  # rad (EulerAngles x)
        ("pitch", "f8"),  # rad (EulerAngles y)
        ("yaw", "f8"),  # rad (EulerAngles z)
        ("p", "f8"),  # rad/s, RateOfTurn x (roll rate)
        ("q", "f8"),  # rad/s, RateOfTurn y (pitch rate)
        ("r", "f8"),  # rad/s, RateOfTurn z (yaw rate)
        ("ax", "f8"),  # m/s^2, Acceleration x
        ("ay", "f8"),  # m/s^2, Acceleration y
        ("az", "f8"),  # m/s^2, Acceleration z
        ("status", "u4"),  # StatusWord
    ]
)

#: Which sample fields hold the angle and the rate of each decay axis.
AXIS_FIELDS: dict[str, tuple[str, str]] = {"roll": ("roll", "p"), "pitch": ("pitch", "q")}

#: Units of every sample field, for channel metadata and people.
SAMPLE_UNITS: dict[str, str] = {
    "t": "s",
    "ticks": "0.1 ms",
    "host_t": "s since epoch",
    "counter": "-",
    "roll": "rad",
    "pitch": "rad",
    "yaw": "rad",
    "p": "rad/s",
    "q": "rad/s",
    "r": "rad/s",
    "ax": "m/s^2",
    "ay": "m/s^2",
    "az": "m/s^2",
    "status": "bits",
}


def empty_samples(n: int = 0) -> np.ndarray:
    """An array of ``n`` zeroed samples (NaN for the measured quantities)."""
    out = np.zeros(n, dtype=SAMPLE_DTYPE)
    for name in ("roll", "pitch", "yaw", "p", "q", "r", "ax", "ay", "az"):
        out[name] = np.nan
    return out
