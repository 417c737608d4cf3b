"""The FTDI latency timer of a USB serial port: how long the adapter holds bytes before sending them.

An FTDI adapter (and the Xsens USB cable, which is one) sends a short packet only when its latency
timer runs out: 16 ms by default on Linux, so a 400 Hz device's samples arrive ~6 at a time. The
timestamps come from the device clock, so the recording is unaffected; only the live view lags.
``device info`` and ``record`` say so in one line, with how to set 1 ms (docs/protocol.md).
"""

from __future__ import annotations

from pathlib import Path

#: Where Linux publishes usb-serial settings: ``<root>/bus/usb-serial/devices/ttyUSB0/latency_timer``.
SYSFS_ROOT = Path("/sys")
#: Latency timers above this get the note (1 ms is what the udev rule sets).
QUIET_LATENCY_MS = 1


def ftdi_latency_ms(port: str, sysfs_root: Path = SYSFS_ROOT) -> int | None:
    """The latency timer of the FTDI usb-serial device behind ``port`` (links resolved), None when the
    port is not one (no such sysfs file: a pty, an ACM device, a cp210x adapter, not Linux)."""
    name = Path(port).resolve().name
    try:
        text = (sysfs_root / "bus" / "usb-serial" / "devices" / name / "latency_timer").read_text()
        return int(text.strip())
    except (OSError, ValueError):
        return None


def latency_note(port: str, latency_ms: int | None, rate_hz: float) -> str | None:
    """One line on what a latency timer above 1 ms costs at ``rate_hz`` and how to set 1 ms (None: nothing
    to say)."""
    if latency_ms is None or latency_ms <= QUIET_LATENCY_MS:
        return None
    name = Path(port).resolve().name
    burst = max(1, round(latency_ms * rate_hz / 1000))
    return (
        f"USB latency timer of {name} is {latency_ms} ms: at {rate_hz:g} Hz samples arrive ~{burst} at a "
        "time (timestamps stay on the device clock; only the live view lags); for 1 ms: "
        f"echo 1 | sudo tee /sys/bus/usb-serial/devices/{name}/latency_timer, or the udev rule in "
        "docs/protocol.md"
    )
