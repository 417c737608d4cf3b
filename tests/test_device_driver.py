"""The driver against the simulated MTi-G on a real pty, opened through pyserial like hardware."""

from __future__ import annotations

import os

import numpy as np
import pytest

from tankdaq.acquire.release import ReleaseDetector
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator import Faults, SimulatedMTi
from tankdaq.errors import DeviceError, DeviceGone, DeviceNotFound, InputError
from tankdaq.physics.scenario import TICK_MODULUS, DecayScenario
from tankdaq.xsens.constants import MID
from tankdaq.xsens.control import decay_output_configuration

SPEED = 10.0  # the device clock runs ten times faster than the wall clock


def _assert_contiguous(samples: np.ndarray, rate_hz: float) -> None:
    assert np.all(np.diff(samples["counter"].astype(np.int64)) % 65536 == 1)
    assert np.all(np.diff(samples["ticks"]) == round(10_000 / rate_hz))
    assert np.all(np.diff(samples["t"]) > 0)


@pytest.mark.parametrize(("rate_hz", "baud"), [(100, 115200), (400, 460800)])
def test_configure_and_stream_ten_seconds_without_a_gap(rate_hz: int, baud: int) -> None:
    with (
        SimulatedMTi(DecayScenario(rate_hz=rate_hz), speed=SPEED, baud=baud) as sim,
        MTiDriver(sim.link, baud=baud, rate_hz=rate_hz) as driver,
    ):
        info = driver.configure()
        assert not info.legacy
        assert info.product_code == "MTi-G-710-2A8G4"
        assert list(info.configuration) == decay_output_configuration(rate_hz)
        samples = driver.samples(10.0)
    assert samples.size == 10 * rate_hz
    _assert_contiguous(samples, rate_hz)
    assert driver.counters.gaps == 0 and driver.counters.bad_frames == 0
    assert np.all(np.isfinite(samples["roll"])) and np.all(np.isfinite(samples["az"]))
    assert np.all(samples["host_t"] > 0)


def test_samples_are_the_scenario_in_si_units() -> None:
    scenario = DecayScenario(rate_hz=100, seed=3)
    expected, _ = scenario.samples()
    with SimulatedMTi(scenario, speed=SPEED) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        samples = driver.samples(3.0)
    index = np.searchsorted(expected["ticks"] % TICK_MODULUS, samples["ticks"][0] % TICK_MODULUS)
    reference = expected[index : index + samples.size]
    np.testing.assert_array_equal(samples["counter"], reference["counter"])
    for name in ("roll", "pitch", "p", "q", "ax", "az"):  # float32 on the wire, Euler in degrees there
        np.testing.assert_allclose(samples[name], reference[name], rtol=1e-6, atol=1e-6)


def test_unplug_raises_device_gone_and_replug_reconnects() -> None:
    with SimulatedMTi(DecayScenario(rate_hz=100), speed=SPEED) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        assert driver.samples(1.0).size == 100
        old_port = sim.port
        sim.unplug()
        assert not os.path.exists(sim.link)
        with pytest.raises(DeviceGone, match="vanished"):
            driver.samples(5.0)
        sim.replug()
        info = driver.reconnect(timeout_s=5.0)
        assert info.port == sim.link
        samples = driver.samples(2.0)
    assert samples.size == 200
    _assert_contiguous(samples, 100)
    assert old_port  # the pts number may or may not be reused; the stable link is what matters


def test_reconnect_gives_up_with_device_gone_when_nothing_comes_back() -> None:
    with SimulatedMTi(DecayScenario(rate_hz=100), speed=SPEED) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        sim.unplug()
        with pytest.raises(DeviceGone, match="did not come back"):
            driver.reconnect(timeout_s=0.5)


def test_legacy_device_is_driven_with_mtdata() -> None:
    with (
        SimulatedMTi(DecayScenario(rate_hz=100, seed=4), speed=SPEED, legacy=True) as sim,
        MTiDriver(sim.link) as driver,
    ):
        info = driver.configure()
        samples = driver.samples(5.0)
        assert MID.OUTPUT_CONFIGURATION in sim.commands_seen  # tried MTData2 first, got Error 0x04
        assert MID.OUTPUT_MODE in sim.commands_seen
    assert info.legacy and info.product_code == "MTi-G-28A53G35" and info.firmware == "2.4.6"
    assert samples.size == 500
    _assert_contiguous(samples, 100)
    assert np.all(np.isfinite(samples["roll"])) and np.all(np.isfinite(samples["p"]))
    assert np.abs(samples["az"]).mean() == pytest.approx(9.81, abs=0.2)


def test_corrupted_bytes_are_survived_and_counted() -> None:
    # Rates low enough that two faults in one frame (which an 8-bit checksum misses 1 time in 256)
    # stay out of this test: one faulty byte per frame is always caught.
    faults = Faults(corrupt_rate=5e-4, drop_rate=2e-5)
    with (
        SimulatedMTi(DecayScenario(rate_hz=100), speed=SPEED, faults=faults) as sim,
        MTiDriver(sim.link) as driver,
    ):
        driver.configure()
        samples = driver.samples(10.0)
        assert sim.bytes_corrupted > 0
    counters = driver.counters
    assert counters.bad_frames > 0
    assert counters.gaps > 0 and counters.lost >= counters.gaps
    assert 0.8 * 1000 < samples.size < 1000  # most samples survive
    assert samples.size + counters.lost == pytest.approx(1000, abs=3)
    assert np.all(np.abs(samples["roll"]) < np.radians(20))  # no garbage passes the checksum


def test_a_stall_shows_up_as_a_counter_gap() -> None:
    with SimulatedMTi(DecayScenario(rate_hz=100), speed=SPEED) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        before = driver.samples(1.0)
        sim.stall(0.3)  # wall seconds: three device seconds at speed 10
        after = driver.samples(5.0)
    steps = np.diff(np.concatenate((before, after))["counter"].astype(np.int64)) % 65536
    jumps = steps[steps != 1]
    assert driver.counters.gaps == 1 and jumps.size == 1
    assert jumps[0] - 1 == driver.counters.lost
    # The silence is timed on a busy machine: allow the scheduler a few tens of milliseconds.
    assert driver.counters.lost == pytest.approx(300, abs=60)


def test_missing_port_lists_the_ports_that_exist() -> None:
    with SimulatedMTi(speed=SPEED) as sim, pytest.raises(DeviceNotFound) as caught:
        MTiDriver("/dev/ttyUSB-does-not-exist").open()
    message = str(caught.value)
    assert "/dev/ttyUSB-does-not-exist" in message
    assert sim.port in message
    assert caught.value.exit_code == 2


def test_rate_the_baud_cannot_carry_is_refused_with_the_numbers() -> None:
    with (
        SimulatedMTi(speed=SPEED) as sim,
        MTiDriver(sim.link, baud=115200, rate_hz=400) as driver,
        pytest.raises(InputError) as caught,
    ):
        driver.configure()
    message = str(caught.value)
    assert "400 Hz needs 276.0 kbit/s" in message
    assert "115200 baud carries 115.2 kbit/s" in message
    assert "--baud 460800" in message


def test_busy_port_is_a_clear_error() -> None:
    with SimulatedMTi(speed=SPEED) as sim, MTiDriver(sim.link), pytest.raises(DeviceError, match="busy"):
        MTiDriver(sim.link).open()


def test_wrong_baud_says_no_answer_and_the_scan_finds_the_right_one() -> None:
    with SimulatedMTi(speed=SPEED, baud=460800) as sim:
        with (
            MTiDriver(sim.link, baud=115200, config_attempts=5) as driver,
            pytest.raises(DeviceError, match=r"no answer.*--baud"),
        ):
            driver.configure()
        with MTiDriver(sim.link, baud=115200, scan_baud=True, config_attempts=5) as driver:
            info = driver.configure()
    assert info.baud == 460800


def test_device_error_replies_carry_their_names() -> None:
    with SimulatedMTi(speed=SPEED) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        driver.go_to_config()
        with pytest.raises(DeviceError, match=r"error 0x04: message invalid or not implemented"):
            driver.request(MID.RUN_SELFTEST)


def test_release_found_through_the_driver_within_one_sample() -> None:
    scenario = DecayScenario(rate_hz=100, seed=8, runs=2, release_after_s=6.0, decay_s=14.0)
    with SimulatedMTi(scenario, speed=20.0) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        detector = ReleaseDetector(axis="roll")
        samples = []
        for block in driver.stream(duration_s=38.0):
            samples.append(block.samples)
            detector.feed(block.samples)
        truth = sim.truth
    samples = np.concatenate(samples)
    released = [e for e in detector.events_ if e.kind == "released"]
    assert len(released) == 2
    for event, run in zip(released, truth, strict=True):
        unwrapped_release = samples["ticks"][0] + (run.release_ticks - samples["ticks"][0]) % TICK_MODULUS
        first_free = int(np.searchsorted(samples["ticks"], unwrapped_release))
        assert abs(event.index - first_free) <= 1
