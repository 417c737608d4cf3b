"""``tankdaq device ports|info|reset|restore-defaults`` against the simulated MTi on a real pty."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator import SimulatedMTi
from tankdaq.xsens.constants import MID

runner = CliRunner()


@pytest.mark.slow
def test_ports_lists_the_simulated_device_as_xsens(simulator: SimulatedMTi) -> None:
    result = runner.invoke(app, ["device", "ports"])
    assert result.exit_code == 0, result.output
    line = next(line for line in result.stdout.splitlines() if line.startswith(simulator.port))
    assert "Xsens" in line and "077B1A2C" in line and "not USB" in line


@pytest.mark.slow
def test_info_shows_the_device_and_leaves_it_as_found(simulator: SimulatedMTi) -> None:
    with MTiDriver(simulator.link) as driver:
        driver.configure()  # measuring, with the decay outputs
    configured = list(simulator.config)
    result = runner.invoke(app, ["device", "info", "auto"])
    assert result.exit_code == 0, result.output
    out = result.stdout
    for expected in ("device id: 077B1A2C", "product: MTi-G-710-2A8G4", "firmware: 1.8.2", "baud: 115200",
                     "EulerAngles", "at 100 Hz", "state found: measuring"):  # fmt: skip
        assert expected in out
    assert simulator.config == configured and simulator.measuring  # configuration and state as found
    assert MID.OUTPUT_CONFIGURATION in simulator.commands_seen


@pytest.mark.slow
def test_reset_reboots_the_device(simulator: SimulatedMTi) -> None:
    result = runner.invoke(app, ["device", "reset", simulator.link])
    assert result.exit_code == 0, result.output
    assert "rebooted (WakeUp seen)" in result.stdout and MID.RESET in simulator.commands_seen


@pytest.mark.slow
def test_restore_defaults_asks_first_and_yes_skips_the_question(simulator: SimulatedMTi) -> None:
    declined = runner.invoke(app, ["device", "restore-defaults", simulator.link], input="n\n")
    assert declined.exit_code == 1 and "nothing changed" in declined.output
    assert MID.RESTORE_FACTORY_DEF not in simulator.commands_seen
    done = runner.invoke(app, ["device", "restore-defaults", simulator.link, "--yes"])
    assert done.exit_code == 0, done.output
    assert "factory defaults restored" in done.stdout
    seen = simulator.commands_seen
    assert MID.RESTORE_FACTORY_DEF in seen and seen.index(MID.RESTORE_FACTORY_DEF) < seen.index(MID.RESET)


@pytest.mark.parametrize(
    ("args", "code", "mentions"),
    [
        (["device", "info", "/dev/ttyNOPE0"], 2, "no such port"),
        (["device", "info", "/dev/ttyNOPE0", "--baud", "12345"], 2, "not an MTi serial rate"),
        (["record", "--port", "sim", "--draft", "T", "--angle", "8", "--hull", "swath", "--rate", "400",
          "--baud", "115200"], 2,
         "use --baud 460800"),
    ],
)  # fmt: skip
def test_bad_device_input_is_one_line(args: list[str], code: int, mentions: str) -> None:
    result = runner.invoke(app, args)
    assert result.exit_code == code, result.output
    assert mentions in result.output and "Traceback" not in result.output


@pytest.mark.slow
def test_a_busy_port_is_exit_1_one_line_in_a_real_process(simulator: SimulatedMTi) -> None:
    tankdaq = str(Path(sys.executable).with_name("tankdaq"))
    with MTiDriver(simulator.link):  # holds the port
        result = subprocess.run(
            [tankdaq, "device", "info", simulator.link], capture_output=True, text=True, timeout=60
        )
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "busy" in lines[0] and "ModemManager" in lines[0]
