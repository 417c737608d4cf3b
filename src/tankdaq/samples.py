"""The sample: one decoded inertial measurement in SI units, as a numpy record.

The device driver turns MTData2 messages into arrays of ``SAMPLE_DTYPE``; every
later stage (release detection, recording, identification, viewing) eats these
arrays. Angles are in rad and rates in rad/s inside tankdaq; the Xsens wire
format carries Euler angles in degrees, so the conversion happens once, here.
"""

from __future__ import annotations

from dataclasses import dataclass

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


# ---- the status word: what each sample says about itself ----------------------------------------

#: StatusWord bits (LLCP Table 27; xspublic ``xsstatusflag.h``). OrientationValid: the filter's
#: orientation is valid (cleared at start-up and while the sensors clip); clipping, per axis, of the
#: accelerometer (bits 8-10) and the gyroscope (bits 11-13). Bit 19 (ClippingDetected) is not used: an
#: older header puts "Retransmitted" there, and the per-axis bits say the same where they exist.
STATUS_ORIENTATION_VALID = 0x0000_0002
STATUS_CLIP_ACC = 0x0000_0700
STATUS_CLIP_GYR = 0x0000_3800
STATUS_CLIPPING_DETECTED = 0x0008_0000


@dataclass(frozen=True)
class SampleFlags:
    """Per-sample flags of a series of status words (boolean arrays of the same length)."""

    acc_clipped: np.ndarray
    gyro_clipped: np.ndarray
    orientation_invalid: np.ndarray  # cleared OrientationValid after the device first reported it set

    @property
    def clipped(self) -> np.ndarray:
        return self.acc_clipped | self.gyro_clipped

    @property
    def unusable(self) -> np.ndarray:
        """Samples a fit leaves out: a sensor clipped, or the orientation is not valid."""
        return self.clipped | self.orientation_invalid


def sample_flags(
    status: np.ndarray, valid_before: bool = False, oriented: np.ndarray | None = None
) -> SampleFlags:
    """The flags of ``status`` words. OrientationValid counts only in samples that carry an orientation
    (``oriented``, default all: a GNSS message has a status word but no angles) and only from the first
    of those that has it set (``valid_before``: an earlier one did): a device that never sets it does not
    report it (a stream configured without the status word reads 0; a real MTi-G-710 capture's inertial
    messages never set it), and one that has not yet set it is starting up."""
    words = np.asarray(status, dtype=np.uint32)
    carries = np.ones(words.shape, bool) if oriented is None else np.asarray(oriented, dtype=bool)
    valid = (words & STATUS_ORIENTATION_VALID) != 0
    seen = np.logical_or.accumulate(valid & carries) | valid_before if words.size else valid
    return SampleFlags(
        acc_clipped=(words & STATUS_CLIP_ACC) != 0,
        gyro_clipped=(words & STATUS_CLIP_GYR) != 0,
        orientation_invalid=seen & carries & ~valid,
    )


def oriented(samples: np.ndarray) -> np.ndarray:
    """Which samples carry an orientation (roll and pitch measured)."""
    return np.isfinite(samples["roll"]) & np.isfinite(samples["pitch"])


@dataclass
class StatusTally:
    """The status flags of one decay, counted as its samples arrive (``add``) or all at once: clipping
    before the release (the hand's tilt: harmless, noted) and after it (the decay: flagged, those samples
    left out of fits), and samples after the release without a valid orientation (treated alike)."""

    release_t: float
    clipped_before: int = 0
    acc_clipped_after: int = 0
    gyro_clipped_after: int = 0
    clipped_after: int = 0
    invalid_after: int = 0
    first_after_s: float = float("nan")  # since the release: the first and last flagged sample
    last_after_s: float = float("nan")
    valid_seen: bool = False

    def add(self, samples: np.ndarray) -> np.ndarray:
        """Count ``samples`` (``SAMPLE_DTYPE``); returns the mask of the flagged ones after the release."""
        words = np.asarray(samples["status"], dtype=np.uint32)
        carries = oriented(samples)
        flags = sample_flags(words, self.valid_seen, carries)
        self.valid_seen = self.valid_seen or bool(np.any(((words & STATUS_ORIENTATION_VALID) != 0) & carries))
        t = samples["t"]
        after = t >= self.release_t
        self.clipped_before += int(np.count_nonzero(flags.clipped & ~after))
        self.acc_clipped_after += int(np.count_nonzero(flags.acc_clipped & after))
        self.gyro_clipped_after += int(np.count_nonzero(flags.gyro_clipped & after))
        self.clipped_after += int(np.count_nonzero(flags.clipped & after))
        self.invalid_after += int(np.count_nonzero(flags.orientation_invalid & after))
        flagged = flags.unusable & after
        if flagged.any():
            since = t[flagged] - self.release_t
            first = float(since[0]) if np.isnan(self.first_after_s) else self.first_after_s
            self.first_after_s, self.last_after_s = first, float(since[-1])
        return flagged

    def unusable(self, samples: np.ndarray) -> np.ndarray:
        """Which of these samples (counted already, or about to be) a fit leaves out."""
        return sample_flags(samples["status"], self.valid_seen, oriented(samples)).unusable

    @property
    def flagged_after(self) -> bool:
        return bool(self.clipped_after or self.invalid_after)

    def describe_after(self) -> str:
        """One line on the decay's flagged samples ("" when there are none)."""
        if not self.flagged_after:
            return ""
        parts = []
        if self.clipped_after:
            sensors = [
                n
                for n, k in (("gyro", self.gyro_clipped_after), ("accelerometer", self.acc_clipped_after))
                if k
            ]
            parts.append(f"{' and '.join(sensors)} clipped in {self.clipped_after} samples")
        if self.invalid_after:
            parts.append(f"orientation not valid in {self.invalid_after} samples")
        span = f"{self.first_after_s:.2f}-{self.last_after_s:.2f} s after the release"
        return f"{'; '.join(parts)} ({span}): left out of fits"

    def describe_before(self) -> str:
        """One line on clipping during the hand's tilt ("" when none): harmless, the decay starts after."""
        if not self.clipped_before:
            return ""
        return f"clipped in {self.clipped_before} samples before the release (the tilt): harmless"

    def metadata(self) -> dict[str, object]:
        """What a recording's metadata says (flat keys; the span in s since the release)."""
        out: dict[str, object] = {
            "clipped_samples_before_release": self.clipped_before,
            "clipped_samples_after_release": self.clipped_after,
            "gyro_clipped_samples_after_release": self.gyro_clipped_after,
            "acc_clipped_samples_after_release": self.acc_clipped_after,
            "orientation_invalid_samples_after_release": self.invalid_after,
        }
        if self.flagged_after:
            out["flagged_span_after_release_s"] = [round(self.first_after_s, 4), round(self.last_after_s, 4)]
        return out
