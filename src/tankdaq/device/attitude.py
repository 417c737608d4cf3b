"""Roll and pitch of a device without orientation output, from its rate of turn and its accelerometer.

An IMU-class MTi sends rate of turn (body rates p, q, r) and acceleration (specific force), no
orientation. Roll and pitch then come from the Euler-angle rates of the body rates (Z-Y'-X''
kinematics, the convention of the device's own Euler output),

    roll' = p + (q sin roll + r cos roll) tan pitch,    pitch' = q cos roll - r sin roll,

integrated sample by sample, and anchored by gravity: while the model rests or is held (still
water, the hand's hold before the release) the accelerometer's gravity direction gives roll and
pitch, and the gyro's bias is learnt from how the integrated rate drifts away from it. A Kalman
filter with two states per axis (angle, gyro bias) does both: it leans on gravity while the model is
quiet and integrates the gyro alone while it moves (the tilt, the decay), when the accelerometer
also feels the motion (the sensor sits above the roll axis) and would pull the angle.

This is a sample-level stage (bytes -> frames -> samples): ``SampleDecoder`` runs it on every sample
of a session, so the anchor and the bias learnt in the still water carry into the decay.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..physics.sensor import GRAVITY_M_S2

#: The slowest output rate integrated: below it the integration's own error (trapezoids through a 3 s
#: swing of 40 deg: 0.03 deg at 50 Hz, 0.11 deg at 25 Hz) is no longer small beside the gyro's noise.
MIN_RATE_HZ = 50.0
#: Longest step integrated as is; a longer gap (a stall, a re-plug) forgets the angle: the next quiet
#: stretch anchors it again.
MAX_STEP_S = 0.1


def euler_rates(p: float, q: float, r: float, roll: float, pitch: float) -> tuple[float, float]:
    """Roll and pitch rates of body rates p, q, r (rad/s) at ``roll``, ``pitch`` (Z-Y'-X'' kinematics)."""
    sin_roll, cos_roll = math.sin(roll), math.cos(roll)
    return p + (q * sin_roll + r * cos_roll) * math.tan(pitch), q * cos_roll - r * sin_roll


class _Axis:
    """One angle and its gyro bias: state and covariance of a two-state Kalman filter."""

    def __init__(self, angle: float, angle_sd: float, bias_sd: float) -> None:
        self.angle = angle
        self.bias = 0.0
        self.p00, self.p01, self.p11 = angle_sd**2, 0.0, bias_sd**2

    def predict(self, rate: float, dt: float, q_angle: float, q_bias: float) -> None:
        """Integrate the bias-corrected rate; x' = F x with F = [[1, -dt], [0, 1]]."""
        self.angle += rate * dt
        p01 = self.p01 - dt * self.p11
        self.p00 += -2 * dt * self.p01 + dt * dt * self.p11 + q_angle
        self.p01 = p01
        self.p11 += q_bias

    def correct(self, measured: float, r: float) -> None:
        """Fold in an angle measurement of variance ``r`` (the angle wraps at +-pi)."""
        innovation = math.remainder(measured - self.angle, math.tau)
        s = self.p00 + r
        k0, k1 = self.p00 / s, self.p01 / s
        self.angle += k0 * innovation
        self.bias += k1 * innovation
        p00, p01 = self.p00, self.p01
        self.p00 -= k0 * p00
        self.p01 -= k0 * p01
        self.p11 -= k1 * p01


class GyroAttitude:
    """Roll and pitch from rate of turn and acceleration (module docstring); ``fill(samples)`` in order.

    ``gyro_noise_rad_s_rthz``: the gyro's white noise (angle random walk); ``initial_bias_rad_s`` and
    ``initial_bias_sd_rad_s``: the gyro bias (p, q) known before the first sample, and how well (a
    replay starts from the bias the recorder had learnt); ``gravity_noise_rad_rthz``:
    how much to trust the gravity direction while quiet (its noise density, with the small motions of
    a held model in it); ``quiet_rate_rad_s``/``quiet_s``: the smoothed rate stays below this for this
    long before gravity is used, and gravity is used ``delay_s`` late (once the rate after it is
    known to be quiet too: the first instants of a release are not mistaken for rest);
    ``gravity_tolerance``: the specific force's magnitude must be within this fraction of g.
    """

    def __init__(
        self,
        gyro_noise_rad_s_rthz: float = math.radians(0.03),
        gravity_noise_rad_rthz: float = math.radians(0.01),
        bias_walk_rad_s_rthz: float = 1e-6,
        initial_bias_rad_s: tuple[float, float] = (0.0, 0.0),
        initial_bias_sd_rad_s: float = math.radians(0.5),
        quiet_rate_rad_s: float = math.radians(1.5),
        quiet_s: float = 0.5,
        delay_s: float = 0.25,
        smooth_s: float = 0.1,
        gravity_tolerance: float = 0.05,
    ) -> None:
        self.gyro_noise_rad_s_rthz = gyro_noise_rad_s_rthz
        self.gravity_noise_rad_rthz = gravity_noise_rad_rthz
        self.bias_walk_rad_s_rthz = bias_walk_rad_s_rthz
        self.initial_bias_rad_s = initial_bias_rad_s
        self.initial_bias_sd_rad_s = initial_bias_sd_rad_s
        self.quiet_rate_rad_s = quiet_rate_rad_s
        self.quiet_s = quiet_s
        self.delay_s = delay_s
        self.smooth_s = smooth_s
        self.gravity_tolerance = gravity_tolerance
        self._roll: _Axis | None = None
        self._pitch: _Axis | None = None
        self._last_t = math.nan
        self._rate_smooth = math.nan
        self._quiet_for_s = 0.0
        self._integrated = [0.0, 0.0]  # roll and pitch integrated from the rates, never corrected
        self._last_rates: tuple[float, float] | None = None  # the Euler-angle rates of the previous sample
        self._history: deque[tuple[float, float, float, float, float]] = deque()

    @property
    def bias_rad_s(self) -> tuple[float, float]:
        """The learnt gyro bias of the roll (p) and pitch (q) rates (before any sample: the initial one)."""
        if self._roll is None or self._pitch is None:
            return self.initial_bias_rad_s
        return (self._roll.bias, self._pitch.bias)

    def fill(self, samples: np.ndarray) -> np.ndarray:
        """Set ``roll`` and ``pitch`` of ``SAMPLE_DTYPE`` rows (the stream's next) in place; returns them."""
        columns = [samples[name].tolist() for name in ("t", "p", "q", "r", "ax", "ay", "az")]
        roll, pitch = samples["roll"], samples["pitch"]
        for i, (t, p, q, r, ax, ay, az) in enumerate(zip(*columns, strict=True)):
            roll[i], pitch[i] = self._step(t, p, q, r, ax, ay, az)
        return samples

    def _step(
        self, t: float, p: float, q: float, r: float, ax: float, ay: float, az: float
    ) -> tuple[float, float]:
        gravity = (math.atan2(ay, az), math.atan2(-ax, math.hypot(ay, az)))
        dt = t - self._last_t
        self._last_t = t
        if not all(map(math.isfinite, (p, q, r, *gravity))):
            return math.nan, math.nan
        if self._roll is None or self._pitch is None or not 0 < dt <= MAX_STEP_S:
            self._start(*gravity)
            return self._angles()
        roll_axis, pitch_axis = self._roll, self._pitch
        p, q = p - roll_axis.bias, q - pitch_axis.bias
        # trapezoids (the rates are instantaneous), the kinematics taken at the angles predicted for now
        guess = euler_rates(p, q, r, roll_axis.angle, pitch_axis.angle)
        rates = euler_rates(p, q, r, roll_axis.angle + guess[0] * dt, pitch_axis.angle + guess[1] * dt)
        q_angle = self.gyro_noise_rad_s_rthz**2 * dt / 2
        q_bias = self.bias_walk_rad_s_rthz**2 * dt
        last = self._last_rates or rates  # the first step after a start: no earlier rate
        for k, axis in enumerate((roll_axis, pitch_axis)):
            step = (rates[k] + last[k]) / 2 * dt
            axis.predict(step / dt, dt, q_angle, q_bias)
            self._integrated[k] += step
        self._last_rates = rates
        rate = math.hypot(p, q, r)
        smooth = self._rate_smooth
        self._rate_smooth = (
            rate if math.isnan(smooth) else smooth + min(1.0, dt / self.smooth_s) * (rate - smooth)
        )
        quiet = (
            self._rate_smooth < self.quiet_rate_rad_s
            and abs(math.hypot(ax, ay, az) - GRAVITY_M_S2) < self.gravity_tolerance * GRAVITY_M_S2
        )
        self._quiet_for_s = self._quiet_for_s + dt if quiet else 0.0
        self._history.append((t, self._integrated[0], self._integrated[1], *gravity))
        self._correct_delayed(t, dt)
        return self._angles()

    def _correct_delayed(self, t: float, dt: float) -> None:
        """Fold in the gravity direction of ``delay_s`` ago if the model has been quiet since well
        before it: the motion that starts at a release is known only once the rate has risen."""
        assert self._roll is not None and self._pitch is not None
        history = self._history
        while history and history[0][0] <= t - self.delay_s:
            then, integrated_roll, integrated_pitch, gravity_roll, gravity_pitch = history.popleft()
            if self._quiet_for_s < self.quiet_s + (t - then):
                continue
            variance = self.gravity_noise_rad_rthz**2 / dt
            # the estimate of then, moved by every correction since: now, less what was integrated since
            for axis, integrated_then, integrated_now, measured in (
                (self._roll, integrated_roll, self._integrated[0], gravity_roll),
                (self._pitch, integrated_pitch, self._integrated[1], gravity_pitch),
            ):
                axis.correct(measured + (integrated_now - integrated_then), variance)

    def _start(self, gravity_roll: float, gravity_pitch: float) -> None:
        """(Re)start from the gravity direction with a wide uncertainty; a learnt bias is kept."""
        biases = self.bias_rad_s
        wide = math.radians(10.0)
        self._roll = _Axis(gravity_roll, wide, self.initial_bias_sd_rad_s)
        self._pitch = _Axis(gravity_pitch, wide, self.initial_bias_sd_rad_s)
        self._roll.bias, self._pitch.bias = biases
        self._quiet_for_s = 0.0
        self._history.clear()
        self._last_rates = None
        self._rate_smooth = math.nan  # the next rate starts the smoothing

    def _angles(self) -> tuple[float, float]:
        assert self._roll is not None and self._pitch is not None
        return self._roll.angle, self._pitch.angle
