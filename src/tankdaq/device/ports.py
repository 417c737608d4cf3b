"""Finding serial ports: which exist, which is an Xsens device, and where a re-plugged one went.

pyserial's ``serial.tools.list_ports`` is the source for hardware. Stable names come from
``/dev/serial/by-id`` (udev names each USB serial port ``usb-<vendor>_<product>_<serial>-if..``
there), plus the folders named in ``TANKDAQ_SERIAL_BY_ID`` (``:``-separated): the simulated
MTi-G keeps such a folder for its pty, so the same code finds it by serial number after a
re-plug. Classifying a port is a pure function of its ``ListPortInfo``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

from serial.tools import list_ports
from serial.tools.list_ports_common import ListPortInfo

from ..errors import DeviceNotFound, InputError

#: USB vendor ids: Xsens (MTi-100/G-710 native USB, MTi 600-series USB) and FTDI (USB-serial cables).
XSENS_VID = 0x2639
FTDI_VID = 0x0403
SYSTEM_BY_ID = "/dev/serial/by-id"
BY_ID_ENV = "TANKDAQ_SERIAL_BY_ID"
#: ``usb-<vendor>_<product>_<serial>-if<NN>[-port<N>]``: the serial is the last ``_`` field.
_BY_ID_NAME = re.compile(r"^usb-(?P<vendor>[^_]+)_(?P<product>.+)_(?P<serial>[^_]+?)-if\d+(?:-port\d+)?$")


def is_url(port: str) -> bool:
    """pyserial URLs (``loop://``, ``socket://host:port``, ``rfc2217://...``) are not paths."""
    return "://" in port


def path_exists(port: str) -> bool:
    """True for URLs (pyserial decides) and for paths that exist (a dangling symlink does not)."""
    return is_url(port) or os.path.exists(port)


def by_id_dirs() -> list[str]:
    """Folders of stable by-id links: the system's, then those named in ``TANKDAQ_SERIAL_BY_ID``."""
    extra = [d for d in os.environ.get(BY_ID_ENV, "").split(os.pathsep) if d]
    return [SYSTEM_BY_ID, *extra]


def by_id_name(vendor: str, product: str, serial: str) -> str:
    """The link name udev gives a USB serial port (``usb-Xsens_MTi-G-710_03780A2C-if00-port0``)."""
    return f"usb-{vendor}_{product}_{serial}-if00-port0"


class PortKind(StrEnum):
    """What a port is, as ``tankdaq ports`` marks it."""

    XSENS = "xsens"
    FTDI = "ftdi"
    USB = "usb"
    OTHER = "other"


#: The mark ``tankdaq ports`` prints for each kind.
MARKS = {PortKind.XSENS: "Xsens", PortKind.FTDI: "FTDI cable", PortKind.USB: "USB", PortKind.OTHER: "not USB"}


@dataclass(frozen=True)
class PortEntry:
    """One serial port as the lab sees it."""

    device: str
    kind: PortKind
    vid: int | None
    pid: int | None
    serial_number: str | None
    description: str
    link: str | None = None  # a stable by-id link to it, if any

    @property
    def usb(self) -> str:
        return f"{self.vid:04x}:{self.pid:04x}" if self.vid is not None and self.pid is not None else "-"

    def line(self) -> str:
        mark = MARKS[self.kind]
        serial = f"  serial {self.serial_number}" if self.serial_number else ""
        link = f"  ({self.link})" if self.link else ""
        return f"{self.device:24s} {mark:10s} {self.usb:9s} {self.description}{serial}{link}"


def classify(info: ListPortInfo, link: str | None = None) -> PortEntry:
    """What a port is, from pyserial's description of it (and its by-id link name, for non-USB ports)."""
    serial, manufacturer, description = info.serial_number, info.manufacturer, info.description
    named = _BY_ID_NAME.match(os.path.basename(link)) if link else None
    if info.vid is None and named:  # a by-id link to a non-USB port (the simulator's pty)
        manufacturer, serial = named["vendor"], named["serial"]
        description = f"{named['vendor']} {named['product']} (by-id link, not USB)"
    if info.vid == XSENS_VID or (info.vid is None and manufacturer == "Xsens"):
        kind = PortKind.XSENS
    elif info.vid == FTDI_VID:
        kind = PortKind.FTDI
    elif info.vid is not None:
        kind = PortKind.USB
    else:
        kind = PortKind.OTHER
    return PortEntry(info.device, kind, info.vid, info.pid, serial, description or "n/a", link)


def _by_id_links(dirs: Sequence[str]) -> dict[str, str]:
    """Real device path -> by-id link, over the given folders (first link wins; missing folders are empty)."""
    links: dict[str, str] = {}
    for folder in dirs:
        try:
            names = sorted(os.listdir(folder))
        except OSError:
            continue
        for name in names:
            path = os.path.join(folder, name)
            if os.path.exists(path):
                links.setdefault(os.path.realpath(path), path)
    return links


def list_serial_ports(dirs: Sequence[str] | None = None) -> list[PortEntry]:
    """Every serial port pyserial knows, plus the by-id links to ports it does not (ptys)."""
    links = _by_id_links(by_id_dirs() if dirs is None else dirs)
    entries = []
    for info in sorted(list_ports.comports()):
        entries.append(classify(info, links.pop(os.path.realpath(info.device), None)))
    for target, link in sorted(links.items()):
        entries.append(classify(ListPortInfo(target, skip_link_detection=True), link))
    return entries


def resolve_port(port: str, dirs: Sequence[str] | None = None) -> str:
    """``auto`` -> the one Xsens device's path; any other name is returned as given."""
    if port != "auto":
        return port
    entries = list_serial_ports(dirs)
    xsens = [e for e in entries if e.kind == PortKind.XSENS]
    if len(xsens) == 1:
        return xsens[0].link or xsens[0].device
    if not xsens:
        listing = "; ".join(f"{e.device} ({e.kind}, {e.description})" for e in entries) or "none"
        raise DeviceNotFound(
            f"--port auto: no Xsens device (USB vendor 2639) found; ports here: {listing}. "
            "Give the port with --port PATH (tankdaq device ports lists them)"
        )
    listing = "; ".join(f"{e.link or e.device} ({e.description})" for e in xsens)
    raise InputError(f"--port auto: {len(xsens)} Xsens devices found, choose one with --port: {listing}")


def usb_serial_of(path: str, dirs: Sequence[str] | None = None) -> str | None:
    """The USB serial number of the device at ``path`` (None for URLs and ports without one)."""
    if is_url(path) or not os.path.exists(path):
        return None
    real = os.path.realpath(path)
    for entry in list_serial_ports(dirs):
        if os.path.realpath(entry.device) == real and entry.serial_number:
            return entry.serial_number
    return None


def find_by_serial(serial: str, dirs: Sequence[str] | None = None) -> str | None:
    """Where the device with USB serial number ``serial`` is now (after a re-plug), if anywhere."""
    for entry in list_serial_ports(dirs):
        if entry.serial_number == serial:
            return entry.link or entry.device
    return None


def available_ports() -> list[str]:
    """Serial port paths here, for error messages (stable links first)."""
    entries = list_serial_ports()
    return list(dict.fromkeys([*(e.link for e in entries if e.link), *(e.device for e in entries)]))


def describe_missing(port: str) -> str:
    """One line: the port does not exist, and what does."""
    ports = available_ports()
    listing = ", ".join(ports) if ports else "none"
    hint = "" if ports else " (is the USB cable in? is the xsens_mt / ftdi_sio driver loaded?)"
    return (
        f"no such port {port!r}; ports here: {listing}{hint}. "
        "A running `tankdaq simulate` prints its port path on start; `tankdaq device ports` lists them all."
    )
