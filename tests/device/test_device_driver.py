"""The driver against the simulated MTi-G on a real pty, opened through pyserial like hardware."""

from __future__ import annotations

import errno
import os
import pty

import numpy as np
import pytest

from tankdaq.acquire.release import ReleaseDetector
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.link import open_error_message
from tankdaq.device.simulator import Behaviour, DeviceIdentity, Faults, SimulatedMTi
from tankdaq.device.simulator.process import SimulatorProcess
from tankdaq.errors import DeviceError, DeviceGone, DeviceNotFound, InputError
from tankdaq.physics.truth import TICK_MODULUS
from tankdaq.xsens.constants import MID
from tankdaq.xsens.control import decay_output_configuration

SPEED = 10.0  # the device clock runs ten times faster than the wall clock


def _assert_contiguous(samples: np.ndarray, rate_hz: float) -> None:
    assert np.all(np.diff(samples["counter"].astype(np.int64)) % 65536 == 1)
    assert np.all(np.diff(samples["ticks"]) == round(10_000 / rate_hz))
    assert np.all(np.diff(samples["t"]) > 0)


@pytest.mark.parametrize(("rate_hz", "baud"), [(100, 115200), (400, 460800)])
@pytest.mark.slow
def test_configure_and_stream_ten_seconds_without_a_gap(rate_hz: int, baud: int) -> None:
    # the device in a process of its own, as hardware: a simulator thread here would share this
    # interpreter with the reader, and under load the reader fell behind the device's buffer
    with (
        SimulatorProcess(hull_scenario(rate_hz=rate_hz), speed=SPEED, baud=baud) as sim,
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
    scenario = hull_scenario(rate_hz=100, seed=3)
    expected, _ = scenario.samples()
    with SimulatedMTi(scenario, speed=SPEED) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        samples = driver.samples(3.0)
    index = np.searchsorted(expected["ticks"] % TICK_MODULUS, samples["ticks"][0] % TICK_MODULUS)
    reference = expected[index : index + samples.size]
    np.testing.assert_array_equal(samples["counter"], reference["counter"])
    for name in ("roll", "pitch", "p", "q", "ax", "az"):  # float32 on the wire, Euler in degrees there
        np.testing.assert_allclose(samples[name], reference[name], rtol=1e-6, atol=1e-6)


def test_unplug_raises_device_gone_and_replug_reconnects(simulator: SimulatedMTi) -> None:
    with MTiDriver(simulator.link) as driver:
        driver.configure()
        assert driver.samples(1.0).size == 100
        old_port = simulator.port
        simulator.unplug()
        assert not os.path.exists(simulator.link)
        with pytest.raises(DeviceGone, match="vanished"):
            driver.samples(5.0)
        simulator.replug()
        info = driver.reconnect(timeout_s=5.0)
        assert info.port == simulator.link
        samples = driver.samples(2.0)
    assert samples.size == 200
    _assert_contiguous(samples, 100)
    assert old_port  # the pts number may or may not be reused; the stable link is what matters


@pytest.mark.slow
def test_reconnect_gives_up_with_device_gone_when_nothing_comes_back(simulator: SimulatedMTi) -> None:
    with MTiDriver(simulator.link) as driver:
        driver.configure()
        simulator.unplug()
        with pytest.raises(DeviceGone, match="did not come back"):
            driver.reconnect(timeout_s=0.5)


@pytest.mark.slow
def test_legacy_device_is_driven_with_mtdata() -> None:
    with (
        SimulatedMTi(hull_scenario(rate_hz=100, seed=4), speed=SPEED, legacy=True) as sim,
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


@pytest.mark.slow
def test_corrupted_bytes_are_survived_and_counted() -> None:
    # Rates low enough that two faults in one frame (which an 8-bit checksum misses 1 time in 256)
    # stay out of this test: one faulty byte per frame is always caught.
    faults = Faults(corrupt_rate=5e-4, drop_rate=2e-5)
    with (
        SimulatedMTi(hull_scenario(rate_hz=100), speed=SPEED, faults=faults) as sim,
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
    assert counters.bad_checksums > 0 and counters.skipped_bytes > 0
    assert set(counters.metadata()) >= {"link_bad_checksums", "link_skipped_bytes", "link_false_syncs"}


@pytest.mark.slow
def test_a_stall_shows_up_as_a_counter_gap(simulator: SimulatedMTi) -> None:
    with MTiDriver(simulator.link) as driver:
        driver.configure()
        before = driver.samples(1.0)
        simulator.stall(
            3.0
        )  # device seconds from the next sample: exactly 300 samples, whatever the scheduling
        after = driver.samples(5.0)
    steps = np.diff(np.concatenate((before, after))["counter"].astype(np.int64)) % 65536
    jumps = steps[steps != 1]
    assert driver.counters.gaps == 1 and jumps.size == 1
    assert jumps[0] - 1 == driver.counters.lost == 300


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


def test_busy_port_is_a_clear_error_naming_modemmanager() -> None:
    with SimulatedMTi(speed=SPEED) as sim, MTiDriver(sim.link), pytest.raises(DeviceError) as caught:
        MTiDriver(sim.link).open()
    message = str(caught.value)
    assert "busy" in message and "ModemManager" in message and "ID_MM_DEVICE_IGNORE" in message
    assert "\n" not in message


def test_permission_denied_names_the_dialout_group_and_the_command() -> None:
    message = open_error_message("/dev/ttyUSB0", PermissionError(errno.EACCES, "Permission denied"))
    assert "dialout" in message and "sudo usermod -aG dialout $USER" in message


@pytest.mark.slow
def test_a_device_at_another_rate_is_found_by_the_search() -> None:
    with SimulatedMTi(speed=SPEED, baud=460800) as sim, MTiDriver(sim.link) as driver:
        info = driver.configure()
        assert driver.samples(1.0).size == 100
    assert info.baud == 460800 and info.baud_changed_from is None  # it carries 100 Hz: left there


@pytest.mark.slow
def test_a_silent_port_says_what_was_tried_and_what_to_check() -> None:
    master, slave = pty.openpty()  # a real port with nothing behind it
    try:
        driver = MTiDriver(os.ttyname(slave), goto_config_s=0.3, probe_s=0.05, boot_s=0.3)
        with driver, pytest.raises(DeviceError) as caught:
            driver.configure()
    finally:
        os.close(master)
        os.close(slave)
    message = str(caught.value)
    assert "GoToConfig for 0.3 s at 115200 baud" in message
    assert "0.05 s at each of 921600, 460800" in message
    assert "then Reset at 115200 baud and GoToConfig for 0.3 s (WakeUp not seen)" in message
    assert "received nothing" in message and "ModemManager" in message
    assert "--scan-baud" not in message and "\n" not in message


@pytest.mark.slow
def test_a_device_stuck_in_measurement_is_reset_and_its_wakeup_answered() -> None:
    stuck = Behaviour(stuck=True, boot_s=1.7)  # the field report: GoToConfig acked ~1.7 s after Reset
    with (
        SimulatedMTi(hull_scenario(rate_hz=100), speed=SPEED, behaviour=stuck) as sim,
        MTiDriver(sim.link) as driver,
    ):
        info = driver.configure()
        samples = driver.samples(2.0)
        seen = list(sim.commands_seen)
    assert seen.count(MID.RESET) == 1 and MID.WAKEUP_ACK in seen
    assert seen.index(MID.RESET) < seen.index(MID.WAKEUP_ACK) < seen.index(MID.GOTO_MEASUREMENT)
    assert info.product_code == "MTi-G-710-2A8G4" and samples.size == 200
    _assert_contiguous(samples, 100)


@pytest.mark.slow
def test_slow_flash_writes_get_their_own_timeout() -> None:
    slow = Behaviour(flash_write_s=0.5)
    with SimulatedMTi(hull_scenario(rate_hz=100), speed=SPEED, behaviour=slow) as sim:
        with MTiDriver(sim.link, flash_timeout_s=0.2) as hasty, pytest.raises(DeviceError) as caught:
            hasty.configure()
        assert "no reply to SetOutputConfiguration" in str(caught.value) and "0.2 s" in str(caught.value)
        with MTiDriver(sim.link, step_timeout_s=0.3) as driver:  # the default flash timeout is 3 s
            info = driver.configure()
            assert driver.samples(1.0).size == 100
    assert list(info.configuration) == decay_output_configuration(100)


@pytest.mark.slow
def test_record_rate_400_from_115200_moves_the_device_to_921600_without_gaps() -> None:
    with SimulatorProcess(hull_scenario(rate_hz=400), speed=SPEED, baud=115200) as sim:  # as above
        with MTiDriver(sim.link, baud=921600, rate_hz=400) as driver:
            info = driver.configure()
            samples = driver.samples(5.0)
        assert sim.baud == 921600 and MID.SET_BAUDRATE in [m.mid for m in sim.received if m.heard]
    assert (info.baud, info.baud_changed_from) == (921600, 115200)
    assert samples.size == 2000 and driver.counters.gaps == 0
    _assert_contiguous(samples, 400)


@pytest.mark.slow
def test_without_baud_the_slowest_rate_that_carries_the_output_is_chosen() -> None:
    with (
        SimulatedMTi(hull_scenario(rate_hz=400), speed=SPEED) as sim,
        MTiDriver(sim.link, rate_hz=400) as driver,
    ):
        info = driver.configure()
        assert driver.samples(1.0).size == 400
    assert (info.baud, info.baud_changed_from) == (460800, 115200)


@pytest.mark.slow
def test_a_600_series_device_is_moved_with_port_config() -> None:
    with SimulatedMTi(hull_scenario(rate_hz=400), speed=SPEED, identity=DeviceIdentity.mti_630()) as sim:
        with MTiDriver(sim.link, baud=921600, rate_hz=400) as driver:
            info = driver.configure()
            samples = driver.samples(2.0)
        seen = list(sim.commands_seen)
    assert MID.SET_PORT_CONFIG in seen and MID.SET_BAUDRATE not in seen
    assert info.product_code == "MTi-630-2A8G4" and info.device_id == 0x0880_0000_0000_1A2C
    assert (info.baud, info.baud_changed_from) == (921600, 115200)
    assert samples.size == 800
    _assert_contiguous(samples, 400)


@pytest.mark.slow
def test_a_replug_under_a_new_name_is_found_by_usb_serial_number(simulator: SimulatedMTi) -> None:
    with MTiDriver(simulator.port) as driver:
        driver.configure()  # opened by its /dev/pts name, which will not come back
        first_name = simulator.port
        assert driver.usb_serial == simulator.identity.serial_number
        simulator.unplug()
        with pytest.raises(DeviceGone):
            driver.samples(5.0)
        simulator.replug()
        info = driver.reconnect(timeout_s=5.0)
        samples = driver.samples(1.0)
        assert simulator.port != first_name  # (another program may own that pts number by now)
        assert os.path.realpath(info.port) == simulator.port
        assert os.path.basename(info.port).startswith("usb-Xsens_MTi-G-710-2A8G4_077B1A2C")
    assert samples.size == 100


def test_device_error_replies_carry_their_names() -> None:
    with SimulatedMTi(speed=SPEED) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        driver.go_to_config()
        with pytest.raises(DeviceError, match=r"error 0x04: message invalid or not implemented"):
            driver.request(MID.RUN_SELFTEST)


@pytest.mark.slow
def test_release_found_through_the_driver_within_one_sample() -> None:
    scenario = hull_scenario(rate_hz=100, seed=8, runs=2, release_after_s=6.0, decay_s=14.0)
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
