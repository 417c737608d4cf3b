"""``tankdaq device info`` changes nothing: no Reset, baud change or flash write, whatever the device's
state; a port that never answers is one line with the advice; the FTDI latency timer is read from sysfs."""

from __future__ import annotations

import os
import pty
import select
import threading
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.latency import ftdi_latency_ms, latency_note
from tankdaq.device.simulator import Behaviour, DeviceIdentity, SimulatedMTi
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame

runner = CliRunner()

#: What would change a device: reboot, line rate, anything written to flash.
CHANGES = {
    MID.RESET, MID.SET_BAUDRATE, MID.SET_PORT_CONFIG, MID.RESTORE_FACTORY_DEF, MID.OUTPUT_CONFIGURATION,
    MID.OUTPUT_MODE, MID.OUTPUT_SETTINGS, MID.PERIOD, MID.WAKEUP_ACK,
}  # fmt: skip

STATES = {
    "obliging": (Behaviour(), DeviceIdentity.mti_g_710()),
    "stuck": (Behaviour(stuck=True), DeviceIdentity.mti_g_710()),
    "slow flash": (Behaviour(flash_write_s=0.5), DeviceIdentity.mti_g_710()),
    "booting": (Behaviour(boot_s=0.3), DeviceIdentity.mti_g_710()),
    "measuring at start": (Behaviour(measuring_at_start=True), DeviceIdentity.mti_g_710()),
    "legacy MTi-G": (Behaviour(), DeviceIdentity.legacy_mti_g()),
    "MTi-630": (Behaviour(), DeviceIdentity.mti_630()),
}


@pytest.mark.parametrize("state", list(STATES))
@pytest.mark.slow
def test_info_writes_nothing_that_changes_the_device(state: str) -> None:
    behaviour, identity = STATES[state]
    legacy = identity == DeviceIdentity.legacy_mti_g()
    with SimulatedMTi(hull_scenario(rate_hz=100), speed=10.0, behaviour=behaviour, identity=identity,
                      legacy=legacy) as sim:  # fmt: skip
        if behaviour.boot_s:
            sim.firmware.power_up(behaviour.boot_s)  # info comes while the device boots
        config_before, baud_before = list(sim.config), sim.baud
        result = runner.invoke(app, ["device", "info", sim.link])
        received = sim.received
        config_after, baud_after = list(sim.config), sim.baud
    assert received, "the device heard nothing: the test would prove nothing"
    written = [m for m in received if m.mid in CHANGES and (m.payload or m.mid != MID.OUTPUT_CONFIGURATION)]
    assert written == [] and all(not m.payload for m in received)
    assert config_after == config_before and baud_after == baud_before
    if behaviour.stuck:  # it ignores GoToConfig: one line, exit 1, the advice
        lines = result.output.strip().splitlines()
        assert result.exit_code == 1 and len(lines) == 1
        assert "no answer to GoToConfig" in lines[0] and f"tankdaq device reset {sim.link}" in lines[0]
    else:
        assert result.exit_code == 0, result.output
        assert f"product: {identity.product_code}" in result.stdout


@pytest.mark.slow
def test_a_pty_that_never_answers_gets_gotoconfig_only_and_one_line() -> None:
    master, slave = pty.openpty()  # a real port with nothing behind it (kept open: the bytes stay readable)
    written = bytearray()
    done = threading.Event()

    def drain() -> None:  # read what the driver writes, from the master side, until the command is over
        os.set_blocking(master, False)
        while not done.is_set() or _readable(master):
            if _readable(master):
                written.extend(os.read(master, 4096))
            else:
                done.wait(0.05)

    reader = threading.Thread(target=drain)
    reader.start()
    try:
        path = os.ttyname(slave)
        result = runner.invoke(app, ["device", "info", path])
    finally:
        done.set()
        reader.join(timeout=10)
        os.close(master)
        os.close(slave)
    lines = result.output.strip().splitlines()
    assert result.exit_code == 1 and len(lines) == 1, result.output
    assert "no answer to GoToConfig" in lines[0] and "received nothing" in lines[0]
    assert f"run tankdaq device reset {path}" in lines[0]
    go_to_config = build_frame(MID.GOTO_CONFIG)
    assert written and written == go_to_config * (len(written) // len(go_to_config))


def _readable(fd: int) -> bool:
    return bool(select.select([fd], [], [], 0)[0])


def _sysfs(root: Path, name: str, latency: str) -> None:
    folder = root / "bus" / "usb-serial" / "devices" / name
    folder.mkdir(parents=True)
    (folder / "latency_timer").write_text(latency)


def test_latency_timer_is_read_through_the_ports_resolved_name(tmp_path: Path) -> None:
    sysfs = tmp_path / "sys"
    _sysfs(sysfs, "ttyUSB3", "16\n")
    device = tmp_path / "dev" / "ttyUSB3"
    device.parent.mkdir()
    device.touch()
    by_id = tmp_path / "usb-Xsens_MTi-G-710_077B1A2C-if00-port0"
    by_id.symlink_to(device)
    assert ftdi_latency_ms(str(by_id), sysfs) == 16
    note = latency_note(str(by_id), 16, 400)
    assert note is not None and "\n" not in note
    assert "ttyUSB3 is 16 ms" in note and "~6 at a time" in note and "device clock" in note
    assert "echo 1 | sudo tee /sys/bus/usb-serial/devices/ttyUSB3/latency_timer" in note
    assert "udev rule in docs/protocol.md" in note


@pytest.mark.slow
def test_no_latency_line_for_a_port_that_is_not_an_ftdi_usb_serial_device(
    simulator: SimulatedMTi, tmp_path: Path
) -> None:
    sysfs = tmp_path / "sys"
    _sysfs(sysfs, "ttyUSB0", "1\n")  # set to 1 ms: nothing to say
    (sysfs / "bus" / "usb-serial" / "devices" / "ttyUSB1").mkdir()  # a usb-serial without the timer
    assert ftdi_latency_ms("/dev/ttyUSB0", sysfs) == 1 and latency_note("/dev/ttyUSB0", 1, 400) is None
    assert ftdi_latency_ms("/dev/ttyUSB1", sysfs) is None and ftdi_latency_ms("/dev/ttyACM0", sysfs) is None
    with MTiDriver(simulator.link) as driver:
        report = driver.inspect()  # a pty: not in sysfs
    assert report.latency_ms is None and not any("latency" in line for line in report.lines())
