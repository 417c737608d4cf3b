"""The scripted decay scenario: deterministic, physically consistent, truthful about itself."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tankdaq.config.hulls import hull_scenario, load_hull
from tankdaq.errors import InputError
from tankdaq.physics.decay import simulate_decay
from tankdaq.physics.scenario import Handling
from tankdaq.physics.sensor import SensorModel, SensorNoise
from tankdaq.physics.truth import TICK_MODULUS, TICKS_PER_S


@pytest.fixture(scope="module")
def roll_runs():
    scenario = hull_scenario(runs=3, seed=11, noise=SensorNoise.none())
    samples, trace = scenario.samples()
    return scenario, samples, trace


def test_same_seed_same_data_other_seed_other_data() -> None:
    a, _ = hull_scenario(runs=1, seed=5).samples()
    b, _ = hull_scenario(runs=1, seed=5).samples()
    c, _ = hull_scenario(runs=1, seed=6).samples()
    assert np.array_equal(a, b)
    assert not np.allclose(a["roll"], c["roll"])


def test_truth_matches_the_reference_integrator_after_release(roll_runs) -> None:
    scenario, _, trace = roll_runs
    coeffs = load_hull("swath").simulation_model("roll").coefficients(1.0)
    for run in trace.runs:
        assert run.kind == "release"
        assert run.coefficients == coeffs
        i = run.release_index
        # The first free sample is the first at or after the (off-grid) release instant.
        assert trace.t[i] >= run.release_s > trace.t[i - 1]
        stop = i + round(5 * scenario.rate_hz)
        t = np.concatenate(([run.release_s], trace.t[i:stop]))
        angle, rate = simulate_decay(run.coefficients, t, run.angle0_rad, run.rate0_rad_s)
        np.testing.assert_allclose(trace.angle[i:stop], angle[1:], atol=1e-7)
        np.testing.assert_allclose(trace.rate[i:stop], rate[1:], atol=1e-6)
        # Independently of any integrator: the recorded motion satisfies the equation.
        dt = 1 / scenario.rate_hz
        assert np.allclose(
            np.gradient(trace.angle[i:stop], dt)[1:-1], trace.rate[i + 1 : stop - 1], atol=2e-3
        )
        assert np.allclose(np.gradient(trace.rate[i:stop], dt)[1:-1], trace.acc[i + 1 : stop - 1], atol=2e-2)
        assert np.max(np.abs(trace.acc[i:stop])) > 1.0  # rad/s^2: the check is not vacuous


def test_release_state_is_where_the_hand_was(roll_runs) -> None:
    scenario, _, trace = roll_runs
    for run in trace.runs:
        i = run.release_index
        # Held near the set angle, almost still, right up to the release.
        assert abs(abs(math.degrees(run.angle0_rad)) - scenario.angle_deg) < 1.5
        assert abs(math.degrees(run.rate0_rad_s)) < 2.0
        assert abs(trace.angle[i - 1] - run.angle0_rad) < abs(run.rate0_rad_s) / scenario.rate_hz + 1e-4
        expected_ticks = (trace.start_ticks + round(run.release_s * TICKS_PER_S)) % TICK_MODULUS
        assert run.release_ticks == expected_ticks


def test_still_water_before_the_tilt_and_after_the_decay(roll_runs) -> None:
    _, _, trace = roll_runs
    first = trace.runs[0]
    before = trace.t < first.tilt_start_s
    assert np.all(trace.angle[before] == 0.0)
    # 25 s of roll decay brings the swath model below the ITTC 0.5 deg threshold.
    end = trace.t < trace.runs[1].tilt_start_s
    tail = end & (trace.t > trace.runs[1].tilt_start_s - 3)
    assert np.max(np.abs(np.degrees(trace.angle[tail]))) < 0.5


def test_perfect_sensor_reports_the_true_motion(roll_runs) -> None:
    _, samples, trace = roll_runs
    np.testing.assert_allclose(samples["roll"], trace.angle, atol=1e-12)
    np.testing.assert_allclose(samples["p"], trace.rate, atol=1e-12)
    np.testing.assert_array_equal(samples["ticks"], trace.ticks)
    assert np.all(np.diff(samples["ticks"]) == TICKS_PER_S // 100)
    assert np.all(np.diff(samples["counter"].astype(np.int64)) % 65536 == 1)
    # The accelerometer sees gravity tilted by roll, plus the tangential acceleration of its lever arm.
    lever = SensorModel.lever_arm_m
    gravity_y = (samples["ay"] + lever * trace.acc) / (9.81 * np.cos(samples["pitch"]))
    np.testing.assert_allclose(gravity_y, np.sin(samples["roll"]), atol=2e-4)  # ADC step 1.5e-3 m/s^2


@pytest.mark.parametrize(("rate_hz", "gyro_rms_deg_s"), [(100, 0.2), (400, 0.4)])
def test_sensor_noise_levels_are_those_documented(rate_hz: float, gyro_rms_deg_s: float) -> None:
    scenario = hull_scenario(runs=1, seed=2, rate_hz=rate_hz)
    samples, trace = scenario.samples()
    sensor = scenario.sensor()
    angle_error = np.degrees(samples["roll"] - trace.angle - sensor.angle_bias[0])
    rate_error = np.degrees(samples["p"] - trace.rate - sensor.gyro_bias[0])
    assert np.std(angle_error) == pytest.approx(0.02, rel=0.05)
    assert np.std(rate_error) == pytest.approx(gyro_rms_deg_s, rel=0.05)


def test_truth_in_seconds_does_not_depend_on_the_rate() -> None:
    slow = hull_scenario(runs=2, seed=4, rate_hz=100).trace().runs
    fast = hull_scenario(runs=2, seed=4, rate_hz=400).trace().runs
    assert [r.release_s for r in slow] == [r.release_s for r in fast]
    assert [r.release_ticks for r in slow] == [r.release_ticks for r in fast]
    for run in fast:
        assert run.release_index == math.ceil(run.release_s * 400 - 1e-9)


def test_pitch_scenario_moves_the_pitch_channel_with_pitch_coefficients() -> None:
    samples, trace = hull_scenario(runs=1, axis="pitch", seed=3, noise=SensorNoise.none()).samples()
    assert trace.runs[0].coefficients == load_hull("swath").simulation_model("pitch").coefficients(1.0)
    assert np.ptp(samples["pitch"]) > math.radians(10)
    assert np.ptp(samples["roll"]) < math.radians(1)


def test_put_back_runs_have_no_release() -> None:
    trace = hull_scenario(runs=4, seed=1, handling=Handling(put_back_fraction=1.0)).trace()
    assert {r.kind for r in trace.runs} == {"put_back"}
    assert all(r.release_s is None for r in trace.runs)
    assert np.max(np.abs(trace.angle[-100:])) == 0.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"rate_hz": 120},
        {"axis": "yaw"},
        {"release_after_s": 1.0},
        {"angle_deg": 45},
        {"hull": "no-such-hull"},
    ],
)
def test_bad_settings_are_input_errors(kwargs: dict) -> None:
    with pytest.raises(InputError):
        hull_scenario(**kwargs)
