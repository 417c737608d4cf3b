"""Orientation from whatever the device gives (issue 21 item 3), without a device.

Quaternion and rotation matrix give the roll and pitch the device's own Euler output gives (the
conversions, and the whole chain simulator output -> bytes -> samples); the negotiation's wording;
the integrated rate of turn of an IMU-class device on trajectories whose truth is known.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from support.xsens_captures import capture
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.attitude import GyroAttitude
from tankdaq.device.simulator.output import Output, effective_configuration
from tankdaq.physics.scenario import DecayScenario
from tankdaq.physics.sensor import GRAVITY_M_S2, SensorNoise
from tankdaq.samples import empty_samples
from tankdaq.xsens.column_decoder import decode_capture, to_samples
from tankdaq.xsens.control import (
    ORIENTATION_OUTPUTS,
    OrientationSource,
    decay_output_configuration,
    is_imu_class,
)
from tankdaq.xsens.mtdata2 import SPEC_BY_BASE, TYPE_MASK
from tankdaq.xsens.orientation import euler_from_matrix, euler_from_quaternion, quaternion, rotation_matrix
from tankdaq.xsens.timebase import MODULUS_ONE_DAY, SampleTimeUnwrapper

angles = st.tuples(
    st.floats(-math.radians(85), math.radians(85)),  # roll: a ship does not capsize in a decay test
    st.floats(-math.radians(85), math.radians(85)),  # pitch: away from the Z-Y-X singularity at 90 deg
    st.floats(-math.pi + 1e-6, math.pi - 1e-6),
)


@settings(max_examples=60, deadline=None)
@given(angles)
def test_quaternion_and_matrix_give_back_the_euler_angles(euler: tuple[float, float, float]) -> None:
    np.testing.assert_allclose(euler_from_quaternion(quaternion(*euler)), euler, atol=1e-9)
    np.testing.assert_allclose(euler_from_matrix(rotation_matrix(*euler)), euler, atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(angles)
def test_the_conventions_are_the_accelerometers_gravity(euler: tuple[float, float, float]) -> None:
    """Sensor-to-earth: the matrix (column by column on the wire) and the quaternion take the gravity
    an accelerometer at rest feels (the simulator's specific force) to earth's up."""
    roll, pitch, _ = euler
    felt = np.array([-math.sin(pitch), math.sin(roll) * math.cos(pitch), math.cos(roll) * math.cos(pitch)])
    matrix = rotation_matrix(*euler).reshape(3, 3, order="F")
    np.testing.assert_allclose(matrix @ felt, [0, 0, 1], atol=1e-12)
    q0, *vector = quaternion(*euler)
    u = np.array(vector)
    rotated = felt + 2 * np.cross(u, np.cross(u, felt) + q0 * felt)  # q * v * q^-1
    np.testing.assert_allclose(rotated, [0, 0, 1], atol=1e-12)


def test_an_all_zero_quaternion_is_no_angle_and_no_warning() -> None:
    with np.errstate(all="raise"):
        assert np.isnan(euler_from_quaternion(np.zeros((1, 4)))).all()


@pytest.mark.parametrize("orientation", ["Quaternion", "RotationMatrix"])
def test_samples_from_quaternion_or_matrix_frames_equal_those_from_euler_frames(orientation: str) -> None:
    """The simulator's frames with each representation decode to the same roll, pitch and yaw."""
    device_samples, _ = hull_scenario(rate_hz=100, runs=1, seed=3, release_after_s=4.0, decay_s=4.0).samples()
    decoded = {}
    for name in ("EulerAngles", orientation):
        output = Output(items=effective_configuration(decay_output_configuration(100, orientation=name)))
        raw = b"".join(output.encode(device_samples, np.arange(device_samples.size)))
        decoded[name] = to_samples(decode_capture(raw), SampleTimeUnwrapper(MODULUS_ONE_DAY))
    euler, other = decoded["EulerAngles"], decoded[orientation]
    assert other.size == euler.size == device_samples.size
    for field in ("roll", "pitch", "yaw"):  # float32 on the wire: a few micro-radians
        np.testing.assert_allclose(other[field], euler[field], atol=2e-6)
        np.testing.assert_allclose(euler[field], device_samples[field], atol=2e-6)
    np.testing.assert_array_equal(other["p"], euler["p"])


def test_the_decay_outputs_carry_the_orientation_asked_for_or_none() -> None:
    for name in ORIENTATION_OUTPUTS:
        names = [
            SPEC_BY_BASE[xdi & TYPE_MASK].name for xdi, _ in decay_output_configuration(100, orientation=name)
        ]
        assert [n for n in names if n in ORIENTATION_OUTPUTS] == [name]
    names = [
        SPEC_BY_BASE[xdi & TYPE_MASK].name for xdi, _ in decay_output_configuration(100, orientation=None)
    ]
    assert not set(names) & set(ORIENTATION_OUTPUTS) and {"RateOfTurn", "Acceleration"} <= set(names)


def test_imu_class_products_are_told_by_their_product_code() -> None:
    for code in ("MTi-1-8A7G6", "MTi-10-2A5G4", "MTi-100-2A8G4", "MTi-610"):
        assert is_imu_class(code), code
    for code in (
        "MTi-G-710-2A8G4",
        "MTi-30-2A8G4",
        "MTi-300-2A8G4",
        "MTi-630-2A8G4",
        "MTi-G-28A53G35",
        "MTi-1000",
    ):
        assert not is_imu_class(code), code


def test_the_line_and_the_metadata_say_what_was_refused_and_what_is_used() -> None:
    assert OrientationSource().line() is None
    assert OrientationSource().metadata() == {"orientation_source": "Euler angles"}
    quat = OrientationSource("Quaternion", (("EulerAngles", 0x21),))
    assert (
        quat.line() == "the device refused Euler angles (error 0x21): roll and pitch come from its quaternion"
    )
    assert quat.metadata() == {
        "orientation_source": "quaternion",
        "orientation_refused": "Euler angles (error 0x21)",
    }
    matrix = OrientationSource("RotationMatrix", (("EulerAngles", 0x21), ("Quaternion", 0x21)))
    assert matrix.line() == (
        "the device refused Euler angles and quaternion (error 0x21): "
        "roll and pitch come from its rotation matrix"
    )
    imu = OrientationSource(None, imu_class=True)
    assert imu.metadata() == {"orientation_source": "integrated rate of turn"}
    assert imu.line() == (
        "the device is an IMU-class product (no orientation output): roll and pitch come from its rate of "
        "turn integrated over the decay, anchored by gravity at rest before the release"
    )
    refusing_all = OrientationSource(None, tuple((name, 0x21) for name in ORIENTATION_OUTPUTS))
    assert refusing_all.metadata()["orientation_refused"] == (
        "Euler angles (error 0x21), quaternion (error 0x21), rotation matrix (error 0x21)"
    )
    assert str(refusing_all.line()).startswith(
        "the device refused Euler angles, quaternion and rotation matrix (error 0x21): roll and pitch come "
        "from its rate of turn integrated"
    )


# ---- the integrated rate of turn ----------------------------------------


def _rigid_motion(rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Samples of a sensor at rest 6 s, then rolling up to 40 deg, pitching up to 20 deg from a 15 deg
    trim and turning for 20 s (exact body rates from the Z-Y'-X'' kinematics); its accelerometer at
    rest feels gravity, moving it also feels 0.5 m/s^2 of motion. Returns (samples, true roll, pitch)."""
    t = np.arange(round(26 * rate_hz)) / rate_hz
    moving = np.clip(t - 6.0, 0.0, None)
    w = 2 * np.pi / 3.0
    amplitude, trim = math.radians(20), math.radians(15)  # every rate starts from 0, as a real motion does
    roll, roll_dot = amplitude * (1 - np.cos(w * moving)), amplitude * w * np.sin(w * moving)
    pitch = trim + amplitude / 2 * (1 - np.cos(0.7 * w * moving))
    pitch_dot = amplitude / 2 * 0.7 * w * np.sin(0.7 * w * moving)
    yaw_dot = 0.3 * (1 - np.cos(w * moving))
    samples = empty_samples(t.size)
    samples["t"] = t
    samples["p"] = roll_dot - yaw_dot * np.sin(pitch)
    samples["q"] = pitch_dot * np.cos(roll) + yaw_dot * np.sin(roll) * np.cos(pitch)
    samples["r"] = -pitch_dot * np.sin(roll) + yaw_dot * np.cos(roll) * np.cos(pitch)
    g = GRAVITY_M_S2
    samples["ax"] = -g * np.sin(pitch)
    samples["ay"] = g * np.cos(pitch) * np.sin(roll) + 0.5 * (t > 6)
    samples["az"] = g * np.cos(pitch) * np.cos(roll)
    return samples, np.stack((roll, pitch))


@pytest.mark.parametrize("rate_hz", [100.0, 400.0])
def test_the_integrated_rate_of_turn_follows_a_large_3d_motion(rate_hz: float) -> None:
    """Large roll with pitch and yaw: only the kinematic transform keeps roll and pitch (integrating p
    and q alone is off by degrees), and the accelerometer's motion is not taken for gravity."""
    samples, truth = _rigid_motion(rate_hz)
    GyroAttitude().fill(samples)
    moving = samples["t"] > 6
    for k, name in enumerate(("roll", "pitch")):
        error_deg = np.degrees(np.abs(samples[name][moving] - truth[k][moving]))
        assert error_deg.max() < 0.01, (name, error_deg.max())
    naive = np.cumsum(samples["p"]) / rate_hz  # what integrating the body rate alone gives
    assert np.degrees(np.abs(naive[moving] - truth[0][moving])).max() > 1.0


#: A lightly damped roll decay (the swath's period): still oscillating 20 s after the release.
LONG_DECAY = {"b1": 0.2, "c1": 14.2185, "c3": 69.457}


@pytest.mark.parametrize("seed", [4, 14])
def test_the_integrated_rate_of_turn_matches_a_simulated_decay_within_a_tenth_of_a_degree(seed: int) -> None:
    """An MTi-100's noisy gyro and accelerometer over a scripted decay: over the first 20 s after the
    release the roll is within 0.1 deg RMS of the truth, once the static error of the accelerometer's
    bias (which any gravity reference has, and the estimate must show) is set aside; the gyro bias is
    learnt in the still water (about 15 s before the tilt) and the hold."""
    scenario = DecayScenario(rate_hz=100, runs=1, seed=seed, release_after_s=20.0, decay_s=22.0,
                             noise=SensorNoise.mti_100(), coefficients=LONG_DECAY)  # fmt: skip
    samples, trace = scenario.samples()
    attitude = GyroAttitude()
    attitude.fill(samples)
    (run,) = trace.runs
    decay = slice(run.release_index, run.release_index + 20 * 100)
    error = samples["roll"][decay] - trace.angle[decay]
    sensor = scenario.sensor()
    held = float(run.angle0_rad or 0.0)
    static = (sensor.acc_bias[1] * math.cos(held) - sensor.acc_bias[2] * math.sin(held)) / GRAVITY_M_S2
    assert math.degrees(abs(error.mean() - static)) < 0.03
    assert math.degrees(math.sqrt(np.mean((error - static) ** 2))) < 0.1
    assert math.degrees(abs(attitude.bias_rad_s[0] - sensor.gyro_bias[0])) < 0.005


def test_a_real_devices_quaternion_and_rotation_matrix_give_the_same_angles() -> None:
    """A real MTi-G-710 capture (einride set 5) sends both in each message: read column by column, the
    matrix gives the quaternion's roll, pitch and yaw (read row by row it would not: yaw off by ~180 deg)."""
    block = decode_capture(capture("einride-5").read_bytes())
    both = block.present["Quaternion"] & block.present["RotationMatrix"]
    assert both.sum() >= 90
    from_quaternion = euler_from_quaternion(block.columns["Quaternion"][both])
    from_matrix = euler_from_matrix(block.columns["RotationMatrix"][both])
    np.testing.assert_allclose(from_matrix, from_quaternion, atol=1e-6)  # float32 on the wire
    samples = to_samples(block, SampleTimeUnwrapper(MODULUS_ONE_DAY))
    assert samples.size >= 90 and np.isfinite(samples["roll"]).all()  # a quaternion-only stream has roll
