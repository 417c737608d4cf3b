"""The simulated MTi-G at the message level, through a plain pyserial client on its pty."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
import serial

from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator import OWNER_FILE, TEMP_PREFIX, Behaviour, Faults, SimulatedMTi
from tankdaq.errors import DeviceGone, InputError
from tankdaq.xsens.constants import MID, baud_code
from tankdaq.xsens.control import output_configuration_payload, parse_output_configuration
from tankdaq.xsens.frame import Frame, build_frame
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import decode_mtdata2, make_xdi

TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))  # the installed console script


class Client:
    """A bare Xbus client: send a frame, collect frames for a while."""

    def __init__(self, port: str, baud: int = 115200) -> None:
        self.serial = serial.Serial(port, baud, timeout=0.02)
        self.framer = StreamFramer()

    def send(self, mid: int, payload: bytes = b"") -> None:
        self.serial.write(build_frame(mid, payload))

    def collect(self, seconds: float, until: int | None = None) -> list[Frame]:
        frames: list[Frame] = []
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            data = self.serial.read(4096)
            frames += self.framer.feed(data) if data else self.framer.flush()  # a quiet line confirms
            if until is not None and any(f.mid == until for f in frames):
                break
        return frames

    def ask(self, mid: int, payload: bytes = b"") -> Frame:
        self.send(mid, payload)
        replies = [f for f in self.collect(1.0, until=mid + 1) if f.mid in (mid + 1, MID.ERROR)]
        assert replies, f"no reply to {MID(mid).name}"
        return replies[-1]


def _reset(client: Client) -> list[Frame]:
    """Reset the device (a power cycle without unplugging: the port stays open) and collect the boot."""
    client.ask(MID.GOTO_CONFIG)
    client.send(MID.RESET)
    return client.collect(0.3, until=MID.WAKEUP)


@pytest.mark.slow
def test_reset_boots_with_wakeup_and_an_acknowledged_wakeup_keeps_config(simulator: SimulatedMTi) -> None:
    client = Client(simulator.link)
    assert [f.mid for f in _reset(client)][-2:] == [MID.RESET_ACK, MID.WAKEUP]
    client.send(MID.WAKEUP_ACK)
    assert client.collect(0.8) == []  # acknowledged: no data until GoToMeasurement
    assert client.ask(MID.GOTO_MEASUREMENT).mid == MID.GOTO_MEASUREMENT_ACK
    assert any(f.mid == MID.MTDATA2 for f in client.collect(0.3))


@pytest.mark.slow
def test_unacknowledged_wakeup_means_measuring_with_the_stored_configuration(simulator: SimulatedMTi) -> None:
    client = Client(simulator.link)
    assert _reset(client)[-1].mid == MID.WAKEUP
    frames = [f for f in client.collect(1.0) if f.mid == MID.MTDATA2]
    assert frames
    # Factory-like default: counter, time, quaternion and status.
    assert set(decode_mtdata2(frames[-1].payload)) == {
        "PacketCounter",
        "SampleTimeFine",
        "Quaternion",
        "StatusWord",
    }


@pytest.mark.slow
def test_output_configuration_is_honoured_and_the_echo_is_effective(simulator: SimulatedMTi) -> None:
    client = Client(simulator.link)
    assert client.ask(MID.GOTO_CONFIG).mid == MID.GOTO_CONFIG_ACK
    requested = [
        (make_xdi("PacketCounter"), 0xFFFF),
        (make_xdi("SampleTimeFine"), 0xFFFF),
        (make_xdi("EulerAngles", "fp1632"), 120),  # not a divisor of 400 Hz: the device makes it 100
        (make_xdi("RateOfTurn", "float64"), 50),
        (0x7010, 4),  # GNSS PVT: this simulated device has none, so it is left out
    ]
    echo = parse_output_configuration(
        client.ask(MID.OUTPUT_CONFIGURATION, output_configuration_payload(requested)).payload
    )
    assert echo == [requested[0], requested[1], (make_xdi("EulerAngles", "fp1632"), 100), requested[3]]
    assert parse_output_configuration(client.ask(MID.OUTPUT_CONFIGURATION).payload) == echo
    client.ask(MID.GOTO_MEASUREMENT)
    messages = [decode_mtdata2(f.payload) for f in client.collect(1.0) if f.mid == MID.MTDATA2]
    ticks = np.array([m["SampleTimeFine"] for m in messages])
    assert np.all(np.diff(ticks) == 100)  # messages at 100 Hz
    with_rate = [m for m in messages if "RateOfTurn" in m]
    assert 0.4 < len(with_rate) / len(messages) < 0.6  # RateOfTurn at 50 Hz: every other message
    assert all(set(m) <= {"PacketCounter", "SampleTimeFine", "EulerAngles", "RateOfTurn"} for m in messages)
    assert messages[0].precision("EulerAngles") == "fp1632"


@pytest.mark.slow
def test_unknown_messages_get_error_0x04(simulator: SimulatedMTi) -> None:
    client = Client(simulator.link)
    client.ask(MID.GOTO_CONFIG)
    reply = client.ask(MID.RUN_SELFTEST)
    assert (reply.mid, reply.payload) == (MID.ERROR, b"\x04")


@pytest.mark.slow
def test_baud_rate_change_applies_after_reset_which_wakes_the_device_up() -> None:
    booting = Behaviour(boot_s=0.3)  # a quiet boot after the Reset ack, as on hardware
    with SimulatedMTi(hull_scenario(rate_hz=100), speed=10.0, behaviour=booting) as sim:
        client = Client(sim.link)
        client.ask(MID.GOTO_CONFIG)
        assert client.ask(MID.REQ_BAUDRATE).payload == bytes((baud_code(115200),))
        assert client.ask(MID.SET_BAUDRATE, bytes((baud_code(460800),))).mid == MID.BAUDRATE_ACK
        assert client.ask(MID.GOTO_CONFIG).mid == MID.GOTO_CONFIG_ACK  # still at the old rate until reset
        client.send(MID.RESET)
        assert [f.mid for f in client.collect(0.5, until=MID.RESET_ACK)][-1] == MID.RESET_ACK
        client.serial.baudrate = 460800  # reopen at the new rate: the WakeUp comes there
        client.framer = StreamFramer()
        assert MID.WAKEUP in [f.mid for f in client.collect(2.0, until=MID.WAKEUP)]
        client.serial.close()
        with MTiDriver(sim.link) as driver:  # looks at 115200 first, finds the device at 460800
            info = driver.configure()
    assert info.baud == 460800 and info.baud_changed_from is None


@pytest.mark.slow
def test_legacy_device_refuses_output_configuration() -> None:
    with SimulatedMTi(legacy=True, speed=10.0) as old:
        client = Client(old.link)
        client.ask(MID.GOTO_CONFIG)
        reply = client.ask(
            MID.OUTPUT_CONFIGURATION, output_configuration_payload([(make_xdi("EulerAngles"), 100)])
        )
        assert (reply.mid, reply.payload) == (MID.ERROR, b"\x04")
        assert client.ask(MID.REQ_FW_REV).payload == bytes((2, 4, 6))


def test_driver_opens_a_pyserial_url(simulator: SimulatedMTi, tmp_path) -> None:
    log = tmp_path / "spy.txt"
    with MTiDriver(f"spy://{simulator.link}?file={log}") as driver:
        driver.configure()
        assert driver.samples(0.5).size == 50
    assert log.stat().st_size > 0  # the spy handler saw the traffic


@pytest.mark.slow
def test_silence_longer_than_the_timeout_is_a_vanished_device(simulator: SimulatedMTi) -> None:
    with MTiDriver(simulator.link, silence_timeout_s=0.3) as driver:
        driver.configure()
        driver.samples(0.5)
        simulator.stall(20.0)  # device seconds: two wall seconds at speed 10
        with pytest.raises(DeviceGone, match="no data"):
            driver.samples(5.0)


@pytest.mark.slow
def test_scheduled_unplug_and_replug_keep_the_link() -> None:
    """Out for 20 device seconds (2 s of wall time at speed 10): the link is looked at while it is."""
    faults = Faults(unplug_at_s=3.0, replug_after_s=20.0)
    with SimulatedMTi(hull_scenario(rate_hz=100), speed=10.0, faults=faults) as device:
        link = device.link
        assert device.wait_plugged(False, timeout_s=30.0)
        assert not device.plugged and not os.path.exists(link)
        assert device.wait_plugged(True, timeout_s=30.0)
        assert os.readlink(link) == device.port


@pytest.mark.parametrize("text", ["corrupt=2", "stall=abc", "explode=1"])
def test_bad_fault_specs_are_input_errors(text: str) -> None:
    with pytest.raises(InputError):
        Faults.parse(text)


def test_fault_spec_parses() -> None:
    assert Faults.parse("corrupt=0.001,drop=1e-4,stall=2@30,unplug=60,replug=5") == Faults(
        corrupt_rate=0.001, drop_rate=1e-4, stall_at_s=30.0, stall_s=2.0, unplug_at_s=60.0, replug_after_s=5.0
    )


def _folders_of(pid: int) -> list[Path]:
    """Simulator folders in the temp dir whose owner file names ``pid``."""
    root = Path(tempfile.gettempdir())
    return [f for f in root.glob(f"{TEMP_PREFIX}*") if (f / OWNER_FILE).is_file()
            and (f / OWNER_FILE).read_text().strip() == str(pid)]  # fmt: skip


@pytest.mark.slow
def test_a_folder_left_by_kill_9_is_swept_at_the_next_start() -> None:
    process = subprocess.Popen(
        [TANKDAQ, "simulate", "--speed", "5"], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    try:
        folder = Path(process.stdout.readline().decode().strip()).parent  # type: ignore[union-attr]
        assert folder.is_dir() and _folders_of(process.pid) == [folder]
    finally:
        process.kill()  # SIGKILL: no clean-up runs
        process.communicate(timeout=10)
    assert folder.is_dir()  # left behind, as a killed process leaves it
    with SimulatedMTi(speed=10.0) as sim:
        assert not folder.exists()  # swept: its owner is dead
        assert Path(sim.by_id_dir).is_dir()
    assert not Path(sim.by_id_dir).parent.exists()  # and this one cleaned on stop


@pytest.mark.slow
def test_an_error_exit_of_simulate_leaves_no_folder(tmp_path: Path) -> None:
    bad_truth = tmp_path / "missing-dir" / "truth.json"  # fails after the simulator has started
    process = subprocess.Popen([TANKDAQ, "simulate", "--truth", str(bad_truth)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)  # fmt: skip
    _, err = process.communicate(timeout=60)
    assert process.returncode == 2 and "truth" in err and "Traceback" not in err
    assert _folders_of(process.pid) == []


def test_a_simulator_that_cannot_start_leaves_no_folder(tmp_path: Path, private_tempdir: Path) -> None:
    with pytest.raises(FileNotFoundError):  # its link cannot be made: the pty opens, then the start fails
        SimulatedMTi(link=tmp_path / "no-such-folder" / "ttyMTi0").start()
    assert not list(private_tempdir.glob(f"{TEMP_PREFIX}*"))
    assert str(private_tempdir) not in os.environ.get("TANKDAQ_SERIAL_BY_ID", "")


@pytest.mark.slow
def test_decays_played_on_one_device_keep_its_biases() -> None:
    """A session plays each decay as a scenario of its own seed, on one device: its still water keeps one
    level from decay to decay (a sensor's bias does not step; the session's watch would read a step as
    the model moving). Seeds 1 and 2 alone would put the roll biases 0.07 deg apart."""
    device = SimulatedMTi(hull_scenario(rate_hz=100, runs=0, seed=1), speed=10.0)
    with device, MTiDriver(device.link) as driver:
        driver.configure()
        before = np.degrees(driver.samples(3.0)["roll"])
        device.play(hull_scenario(rate_hz=100, runs=1, seed=2))
        after = np.degrees(driver.samples(20.0)["roll"])
    tilted = np.flatnonzero(np.abs(after - before.mean()) > 0.5)
    assert tilted.size, "the played decay's tilt began within 20 device seconds"
    still_after = after[: tilted[0] - 100]  # the still water up to a second before the hand's tilt
    assert still_after.size >= 200
    noise_deg = 0.02 * 3 / np.sqrt(still_after.size)  # three standard errors of a mean of the angle noise
    assert abs(still_after.mean() - before.mean()) < noise_deg + 0.02 * 3 / np.sqrt(before.size)
