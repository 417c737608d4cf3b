"""The simulated MTi-G: noise, biases, quantisation and saturation on top of the true motion.

Kept apart from the scripted scenario so the sensor's imperfections (what the clipping and
noise tests are about) can be read, and changed, in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..samples import (
    SAMPLE_DTYPE,
    STATUS_CLIP_ACC,
    STATUS_CLIP_GYR,
    STATUS_CLIPPING_DETECTED,
    STATUS_ORIENTATION_VALID,
)
from .truth import TICKS_PER_S, ScenarioTrace

GRAVITY_M_S2 = 9.81

#: StatusWord of a healthy MTi-G streaming: self-test passed (bit 0), filter valid (bit 1).
STATUS_OK = 0x00000003


@dataclass(frozen=True)
class SensorNoise:
    """MTi-G measurement imperfections; the defaults sit in the range of the datasheets.

    MTi-G-710 (and the 2007 MTi-G): roll/pitch filter output noise a few hundredths of a
    degree (static accuracy 0.2-0.5 deg is bias, not noise); gyro noise density 0.01-0.05
    deg/s/sqrt(Hz), here 0.028 so that a 100 Hz stream (50 Hz bandwidth) shows 0.2 deg/s rms
    and 400 Hz shows 0.4 deg/s; accelerometer noise density ~0.002 m/s^2/sqrt(Hz). Rate and
    acceleration are quantised by a 16-bit ADC over +-300 deg/s and +-50 m/s^2. Biases are
    drawn once per scenario with the given rms.
    """

    angle_noise_deg: float = 0.02
    angle_bias_deg: float = 0.05
    gyro_noise_deg_s_rthz: float = 0.028
    gyro_bias_deg_s: float = 0.05
    gyro_lsb_deg_s: float = 600.0 / 65536
    acc_noise_m_s2_rthz: float = 0.002
    acc_bias_m_s2: float = 0.02
    acc_lsb_m_s2: float = 100.0 / 65536
    gyro_range_deg_s: float = 300.0  # beyond it the rate of turn saturates and the status word says so
    acc_range_m_s2: float = 50.0

    @classmethod
    def none(cls) -> SensorNoise:
        """A perfect sensor: for checking the truth against the samples."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @classmethod
    def mti_100(cls) -> SensorNoise:
        """An MTi-100-class inertial unit (datasheet: gyro 0.01 deg/s/sqrt(Hz) over +-450 deg/s,
        accelerometer 60 ug/sqrt(Hz) = 0.0006 m/s^2/sqrt(Hz) over +-200 m/s^2); biases as the default."""
        return cls(gyro_noise_deg_s_rthz=0.01, gyro_lsb_deg_s=900.0 / 65536, acc_noise_m_s2_rthz=0.0006,
                   acc_lsb_m_s2=400.0 / 65536)  # fmt: skip


class SensorModel:
    """Turns true motion into MTi-G samples: biases fixed per seed, fresh noise per block."""

    heading_deg = 30.0
    lever_arm_m = 0.15  # sensor height above the rotation axis: adds tangential and centripetal acceleration

    def __init__(
        self,
        noise: SensorNoise,
        rate_hz: float,
        seed: int,
        start_counter: int = 0,
        bias_seed: int | None = None,
    ) -> None:
        self.noise = noise
        self.rate_hz = rate_hz
        self.seed = seed
        self.start_counter = start_counter
        bias_rng = np.random.default_rng([seed if bias_seed is None else bias_seed, 3])
        self.angle_bias = np.radians(noise.angle_bias_deg) * bias_rng.standard_normal(3)
        self.gyro_bias = np.radians(noise.gyro_bias_deg_s) * bias_rng.standard_normal(3)
        self.acc_bias = noise.acc_bias_m_s2 * bias_rng.standard_normal(3)

    def measure(self, trace: ScenarioTrace, block: int = 0) -> np.ndarray:
        """``SAMPLE_DTYPE`` samples of the trace; ``block`` seeds the noise of successive pieces."""
        rng = np.random.default_rng([self.seed, 4, block])
        n = len(trace)
        nz = self.noise
        nyquist_rthz = math.sqrt(self.rate_hz / 2)
        main, other = trace.angle, trace.other_angle
        roll, pitch = (main, other) if trace.axis == "roll" else (other, main)
        roll_rate, pitch_rate = (
            (trace.rate, trace.other_rate) if trace.axis == "roll" else (trace.other_rate, trace.rate)
        )
        # the gyro measures body rates: the Euler-angle rates through the Z-Y'-X'' kinematics (no yaw rate)
        p, q, r = roll_rate, pitch_rate * np.cos(roll), -pitch_rate * np.sin(roll)
        out = np.zeros(n, dtype=SAMPLE_DTYPE)
        out["ticks"] = trace.ticks
        out["t"] = out["ticks"] / TICKS_PER_S
        out["counter"] = (np.round(trace.t * self.rate_hz).astype(np.int64) + self.start_counter) & 0xFFFF
        out["status"] = STATUS_OK
        angle_sd = math.radians(nz.angle_noise_deg)
        for k, (name, value) in enumerate(
            (("roll", roll), ("pitch", pitch), ("yaw", math.radians(self.heading_deg)))
        ):
            out[name] = value + self.angle_bias[k] + angle_sd * rng.standard_normal(n)
        gyro_sd = math.radians(nz.gyro_noise_deg_s_rthz) * nyquist_rthz
        gyro_range = math.radians(nz.gyro_range_deg_s)
        for k, (name, value) in enumerate((("p", p), ("q", q), ("r", r))):
            sensed = value + self.gyro_bias[k] + gyro_sd * rng.standard_normal(n)
            quantised = _quantise(sensed, math.radians(nz.gyro_lsb_deg_s))
            out[name] = _saturate(out, quantised, gyro_range, STATUS_CLIP_GYR, k)
        specific_force = self._specific_force(trace, roll, pitch)
        acc_sd = nz.acc_noise_m_s2_rthz * nyquist_rthz
        for k, name in enumerate(("ax", "ay", "az")):
            sensed = specific_force[k] + self.acc_bias[k] + acc_sd * rng.standard_normal(n)
            out[name] = _saturate(
                out, _quantise(sensed, nz.acc_lsb_m_s2), nz.acc_range_m_s2, STATUS_CLIP_ACC, k
            )
        return out

    def _specific_force(self, trace: ScenarioTrace, roll: np.ndarray, pitch: np.ndarray) -> list[np.ndarray]:
        """Gravity seen in the body frame, plus lever-arm and heave accelerations (small-angle kinematics)."""
        g = GRAVITY_M_S2
        fx = -g * np.sin(pitch)
        fy = g * np.cos(pitch) * np.sin(roll)
        fz = g * np.cos(pitch) * np.cos(roll) + trace.heave_acc_m_s2 - self.lever_arm_m * trace.rate**2
        if trace.axis == "roll":
            fy = fy - self.lever_arm_m * trace.acc
        else:
            fx = fx + self.lever_arm_m * trace.acc
        return [fx, fy, fz]


def _saturate(out: np.ndarray, values: np.ndarray, limit: float, clip_bits: int, axis: int) -> np.ndarray:
    """``values`` held within +-``limit``; where they are not, ``out``'s status word gets the axis's clip
    bit and ClippingDetected, and loses OrientationValid (an MTi's filter is not valid while it clips)."""
    clipped = np.abs(values) > limit
    if clipped.any():
        axis_bit = (clip_bits & -clip_bits) << axis  # the lowest bit of the sensor's three, then the axis
        out["status"][clipped] = (out["status"][clipped] | axis_bit | STATUS_CLIPPING_DETECTED) & ~np.uint32(
            STATUS_ORIENTATION_VALID
        )
    return np.clip(values, -limit, limit)


def _quantise(values: np.ndarray, step: float) -> np.ndarray:
    return np.round(values / step) * step if step > 0 else values
