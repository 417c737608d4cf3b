"""The simulated MTi-G in a process of its own (``SimulatorProcess``, what ``--port sim`` runs): it is
opened by path like hardware, its refusals reach the caller as they were raised, what it heard stays
readable once stopped, and it leaves no process, pty or by-id folder behind."""

from __future__ import annotations

import os
import select
from pathlib import Path

import pytest

from tankdaq.device.driver import MTiDriver
from tankdaq.device.ports import BY_ID_ENV
from tankdaq.device.simulator.process import SimulatorProcess
from tankdaq.errors import DeviceError, InputError
from tankdaq.xsens.constants import MID


def _ended(pid: int) -> bool:
    """Whether process ``pid`` has ended (waited for on its pidfd, bounded)."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        return True
    try:
        return bool(select.select([fd], [], [], 10.0)[0])
    finally:
        os.close(fd)


def test_a_refused_setting_is_the_same_one_line_and_no_process_is_left() -> None:
    device = SimulatorProcess(speed=-1.0)
    with pytest.raises(InputError, match="speed must be positive, got -1"):
        device.start()
    assert device.pid is None


@pytest.mark.parametrize("speed", [float("nan"), float("inf"), 1e400, "2", True])
def test_a_speed_that_is_not_a_finite_number_is_refused_in_one_line(speed: object) -> None:
    """Refused where the device is made, not as a traceback of its thread and a device that never speaks."""
    device = SimulatorProcess(speed=speed)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^speed must be a finite number \(.*\), got ") as refused:
        device.start()
    assert "\n" not in str(refused.value) and device.pid is None


@pytest.mark.slow
def test_the_device_streams_from_its_process_and_is_gone_with_it() -> None:
    with SimulatorProcess(speed=4.0, seed=3) as device:
        pid = device.pid
        assert pid is not None and pid != os.getpid()
        assert device.by_id_dir in os.environ[BY_ID_ENV].split(os.pathsep)
        driver = MTiDriver(device.link, probe_first=device.baud)
        try:
            info = driver.configure()
            assert info.device_id and Path(device.port).exists()
        finally:
            driver.close()
        assert device.truth and device.truth[0].kind == "release"
    assert _ended(pid)
    assert not Path(device.link).exists() and not Path(device.by_id_dir).exists()
    assert device.by_id_dir not in os.environ.get(BY_ID_ENV, "").split(os.pathsep)
    heard = [message.mid for message in device.received]  # kept from the device's answer to stop
    assert MID.GOTO_CONFIG in heard and MID.GOTO_MEASUREMENT in heard
    assert device.truth[0].kind == "release"
    with pytest.raises(DeviceError, match="not running"):
        device.unplug()
