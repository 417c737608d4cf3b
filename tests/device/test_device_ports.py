"""Port listing and classification: pyserial's own ListPortInfo, the simulator's by-id folder, --port auto."""

from __future__ import annotations

import os

import pytest
from serial.tools.list_ports_common import ListPortInfo

from tankdaq.device.ports import (
    BY_ID_ENV,
    by_id_name,
    classify,
    find_by_serial,
    list_serial_ports,
    resolve_port,
    usb_serial_of,
)
from tankdaq.device.simulator import DeviceIdentity, SimulatedMTi
from tankdaq.errors import DeviceNotFound, InputError


def _usb_port(device: str, vid: int, pid: int, serial: str, product: str) -> ListPortInfo:
    """What pyserial's Linux backend makes of a USB serial adapter (the fields it fills from sysfs)."""
    info = ListPortInfo(device, skip_link_detection=True)
    info.vid, info.pid, info.serial_number, info.product = vid, pid, serial, product
    info.manufacturer = "Xsens" if vid == 0x2639 else "FTDI"
    info.apply_usb_info()
    return info


@pytest.mark.parametrize(
    ("vid", "pid", "kind"),
    [(0x2639, 0x0100, "xsens"), (0x2639, 0x0300, "xsens"), (0x0403, 0x6001, "ftdi"), (0x1A86, 0x7523, "usb")],
)
def test_usb_ports_are_classified_by_vendor(vid: int, pid: int, kind: str) -> None:
    entry = classify(_usb_port("/dev/ttyUSB0", vid, pid, "03880123", "MTi-G-710 GNSS/INS"))
    assert entry.kind == kind and entry.usb == f"{vid:04x}:{pid:04x}"
    assert entry.serial_number == "03880123" and entry.description == "MTi-G-710 GNSS/INS"
    assert entry.line().startswith("/dev/ttyUSB0")


def test_a_plain_serial_port_is_not_usb() -> None:
    entry = classify(ListPortInfo("/dev/ttyS0", skip_link_detection=True))
    assert (entry.kind, entry.usb, entry.serial_number) == ("other", "-", None)


def test_a_by_id_link_to_a_pty_names_its_vendor_and_serial() -> None:
    link = "/tmp/x/by-id/" + by_id_name("Xsens", "MTi-G-710-2A8G4", "077B1A2C")
    entry = classify(ListPortInfo("/dev/pts/7", skip_link_detection=True), link)
    assert (entry.kind, entry.vid, entry.serial_number) == ("xsens", None, "077B1A2C")
    assert "not USB" in entry.description


def test_the_simulator_is_listed_found_by_serial_and_picked_by_auto() -> None:
    with SimulatedMTi(speed=10.0) as sim:
        assert sim.by_id_dir in os.environ[BY_ID_ENV].split(os.pathsep)
        mine = [e for e in list_serial_ports() if e.link and e.link.startswith(sim.by_id_dir)]
        assert len(mine) == 1 and mine[0].device == sim.port and mine[0].kind == "xsens"
        assert usb_serial_of(sim.port) == sim.identity.serial_number == "077B1A2C"
        assert os.path.realpath(find_by_serial("077B1A2C")) == sim.port
        assert os.path.realpath(resolve_port("auto")) == sim.port
        assert resolve_port("/dev/ttyUSB3") == "/dev/ttyUSB3"  # a path is taken as given
    assert BY_ID_ENV not in os.environ or sim.by_id_dir not in os.environ[BY_ID_ENV]


def test_auto_with_two_xsens_devices_lists_both() -> None:
    with (
        SimulatedMTi(speed=10.0) as one,
        SimulatedMTi(speed=10.0, identity=DeviceIdentity.mti_630()) as two,
        pytest.raises(InputError) as caught,
    ):
        resolve_port("auto")
    message = str(caught.value)
    assert "2 Xsens devices" in message and "077B1A2C" in message and "MTi-630" in message
    assert caught.value.exit_code == 2 and one.port and two.port


def test_auto_without_an_xsens_device_lists_the_ports(tmp_path) -> None:
    with pytest.raises(DeviceNotFound) as caught:
        resolve_port("auto", dirs=[str(tmp_path)])
    assert "no Xsens device" in str(caught.value) and caught.value.exit_code == 2
