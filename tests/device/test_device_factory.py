"""``device.open_device``: the port ``sim`` is the simulated MTi-G on a real pty, any other the driver on that
path; whatever fails while opening stops what was started."""

from __future__ import annotations

from pathlib import Path

import pytest

from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.factory import SIM_REPLY_TIMEOUT_S, DeviceNote, SimulatedSensor, open_device, sim_baud
from tankdaq.errors import DeviceNotFound, InputError

#: Generous deadline for the first samples (reads, not timings, decide the test).
DEADLINE_READS = 500


def _sim(**scenario: object) -> SimulatedSensor:
    """The default decay scenario (with ``scenario``'s settings), played four times faster."""
    return SimulatedSensor(lambda: hull_scenario(runs=1, **scenario), speed=4.0, seed=2)


def _link(notes: list[DeviceNote]) -> Path:
    """The link of the simulated MTi-G the factory said it started (a typed value, not its line)."""
    (link,) = [note.simulator_link for note in notes if note.simulator_link is not None]
    return Path(link)


def test_port_sim_is_the_simulated_sensor_opened_by_path_and_close_stops_it() -> None:
    notes: list[DeviceNote] = []
    device = open_device("sim", rate_hz=100.0, sim=_sim(), on_event=notes.append)
    try:
        assert device.simulator is not None
        assert device.driver.port == device.simulator.link == str(_link(notes))
        assert device.simulator.baud == sim_baud(100.0)
        # a process on a machine busy on every core may answer late; hardware's own timeouts are shorter
        hardware = MTiDriver("/dev/ttyUSB0")
        for timeout in ("step_timeout_s", "flash_timeout_s", "goto_config_s"):
            assert getattr(device.driver, timeout) == SIM_REPLY_TIMEOUT_S > getattr(hardware, timeout)
        samples = 0
        for _ in range(DEADLINE_READS):
            samples += device.driver.read_block().samples.size
            if samples:
                break
        assert samples > 0, "the configured device streams"
    finally:
        device.close()
    assert not _link(notes).exists(), "the simulator stopped: its link is gone"


def test_port_sim_without_a_scenario_is_refused() -> None:
    with pytest.raises(InputError, match="port sim needs a scenario"):
        open_device("sim")


def test_a_device_that_cannot_be_configured_leaves_no_simulator_running() -> None:
    notes: list[DeviceNote] = []
    with pytest.raises(InputError, match="400 Hz needs"):  # 400 Hz does not fit through 115200 baud
        open_device("sim", rate_hz=400.0, baud=115200, sim=_sim(rate_hz=400.0), on_event=notes.append)
    assert not _link(notes).exists()


def test_any_other_port_is_the_driver_on_that_path(tmp_path: Path) -> None:
    with pytest.raises(DeviceNotFound):
        open_device(str(tmp_path / "ttyUSB9"))
