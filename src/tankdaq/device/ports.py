"""Finding serial ports, and saying which ones exist when the one asked for does not."""

from __future__ import annotations

import glob
import os

from serial.tools import list_ports


def is_url(port: str) -> bool:
    """pyserial URLs (``loop://``, ``socket://host:port``, ``rfc2217://...``) are not paths."""
    return "://" in port


def available_ports() -> list[str]:
    """Serial ports the system knows, stable by-id links first, then pseudo-terminals (simulators)."""
    ports = sorted(glob.glob("/dev/serial/by-id/*"))
    ports += sorted(p.device for p in list_ports.comports())
    ports += sorted((p for p in glob.glob("/dev/pts/[0-9]*")), key=lambda p: int(p.rsplit("/", 1)[1]))
    return list(dict.fromkeys(ports))


def describe_missing(port: str) -> str:
    """One line: the port does not exist, and what does."""
    ports = available_ports()
    listing = ", ".join(ports) if ports else "none"
    hint = "" if ports else " (is the USB cable in? is the xsens_mt / ftdi_sio driver loaded?)"
    return (
        f"no such port {port!r}; ports here: {listing}{hint}. "
        "A running `tankdaq simulate` prints its port path on start."
    )


def path_exists(port: str) -> bool:
    """True for URLs (pyserial decides) and for paths that exist (a dangling symlink does not)."""
    return is_url(port) or os.path.exists(port)
