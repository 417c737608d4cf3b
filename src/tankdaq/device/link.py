"""The link to an Xsens device in Config: open the port, framed requests, the hand-shake, inspection.

``device.driver.MTiDriver`` builds on it (output configuration, baud moves, streaming, reconnect);
``inspect`` and ``reset_device`` (``tankdaq device info/reset``) need only this part. The
hand-shake's state machine is in docs/protocol.md and the driver's module docstring.
"""

from __future__ import annotations

import contextlib
import errno
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Self

import serial

from ..errors import DeviceError, DeviceGone, DeviceNotFound, InputError
from ..xsens.constants import FLASH_WRITES, MID, SEARCH_BAUDS
from ..xsens.control import (
    parse_device_id,
    parse_error,
    parse_fw_rev,
    parse_output_configuration,
    parse_product_code,
)
from ..xsens.frame import Frame, build_frame
from ..xsens.framer import StreamFramer
from ..xsens.mtdata2 import describe_xdi
from .latency import ftdi_latency_ms, latency_note
from .ports import describe_missing, path_exists, resolve_port, usb_serial_of

#: GoToConfig is repeated this often while unanswered (the field report's 100 ms).
RESEND_S = 0.1
#: A read returns after this long without bytes: a quiet line, which confirms the frame the framer
#: holds back until it sees what follows (an ack is not delayed by more than this).
READ_TIMEOUT_S = 0.01
#: How long ``inspect`` listens before GoToConfig: a measuring device sends frames by then.
LISTEN_S = 0.25
#: What ``inspect`` may write (all with an empty payload: requests, and the two state changes that
#: take a device to Config and back where it was).
INSPECTION_REQUESTS = frozenset(
    (MID.GOTO_CONFIG, MID.GOTO_MEASUREMENT, MID.REQ_DID, MID.REQ_PRODUCT_CODE, MID.REQ_FW_REV,
     MID.OUTPUT_CONFIGURATION)
)  # fmt: skip
MODEMMANAGER_HINT = (
    "if ModemManager runs it may hold the port: sudo systemctl stop ModemManager, or add the udev rule "
    'ATTRS{idVendor}=="2639", ENV{ID_MM_DEVICE_IGNORE}="1" (see docs/protocol.md)'
)


def open_error_message(port: str, exc: BaseException) -> str:
    """One line for a port that exists but cannot be opened: what is wrong and the command that fixes it."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.EACCES or "Permission denied" in text:
        return (
            f"no permission to open {port}: add yourself to the dialout group "
            "(sudo usermod -aG dialout $USER), then log out and in again"
        )
    if code in (errno.EAGAIN, errno.EBUSY) or "exclusively lock" in text or "busy" in text:
        return f"port {port} is busy: another program has it open (tankdaq? a terminal?); {MODEMMANAGER_HINT}"
    return f"cannot open {port}: {text}"


@dataclass(frozen=True)
class DeviceReport:
    """What ``tankdaq device info`` shows."""

    port: str
    baud: int
    device_id: int
    product_code: str
    firmware: str
    legacy: bool  # a 2007-era MTi-G: no MTData2 output configuration
    configuration: tuple[tuple[int, int], ...]
    was_measuring: bool
    usb_serial: str | None
    latency_ms: int | None = None  # the FTDI latency timer (None: not an FTDI usb-serial port)

    def lines(self) -> list[str]:
        outputs = [f"  {describe_xdi(xdi)} at {'max' if hz in (0, 0xFFFF) else f'{hz} Hz'}"
                   for xdi, hz in self.configuration]  # fmt: skip
        return [
            f"port: {self.port}" + (f" (USB serial {self.usb_serial})" if self.usb_serial else ""),
            f"device id: {self.device_id:08X}",
            f"product: {self.product_code}",
            f"firmware: {self.firmware}",
            f"baud: {self.baud}",
            f"state found: {'measuring' if self.was_measuring else 'config'} (left so)",
            *([note] if (note := latency_note(self.port, self.latency_ms, self._fastest_hz())) else []),
            "output configuration: " + ("legacy MTData (no MTData2 configuration)" if self.legacy else ""),
            *outputs,
        ]

    def _fastest_hz(self) -> float:
        """The fastest output rate configured (the line's bursts are counted in its samples)."""
        rates = [hz for _, hz in self.configuration if hz not in (0, 0xFFFF)]
        return float(max(rates, default=100))


@dataclass
class LineLog:
    """What arrived while looking for the device: the one-line error says it."""

    byte_count: int = 0
    head: bytearray = field(default_factory=bytearray)
    frames: Counter[str] = field(default_factory=Counter)
    wakeup: bool = False

    def add(self, data: bytes, frames: list[Frame]) -> None:
        self.byte_count += len(data)
        self.head += data[: max(0, 12 - len(self.head))]
        self.frames.update(frame.name for frame in frames)
        self.wakeup |= any(frame.mid == MID.WAKEUP for frame in frames)

    def describe(self) -> str:
        if not self.byte_count:
            return "nothing"
        frames = ", ".join(f"{name} x{n}" for name, n in self.frames.most_common(4)) or "no Xbus frame"
        return f"{self.byte_count} bytes ({frames}; first {self.head.hex(' ')})"


class XbusLink:
    """An Xsens device on a serial port (path, pyserial URL or ``auto``), taken to Config: opening,
    framed requests, the GoToConfig search and recovery, identity and the read-only inspection.

    Kept apart from ``MTiDriver`` (which configures the decay outputs on top of it and streams)
    because everything here is about reaching the device, whatever it will be asked to do. Timeouts
    in seconds: ``step_timeout_s`` per request, ``flash_timeout_s`` for flash writes,
    ``goto_config_s`` at the likeliest rate and ``probe_s`` at each other, ``boot_s`` through a reset.
    """

    def __init__(
        self,
        port: str,
        *,
        probe_first: int = 115200,
        line_baud: int | None = None,
        step_timeout_s: float = 1.0,
        flash_timeout_s: float = 3.0,
        goto_config_s: float = 2.0,
        probe_s: float = 0.6,
        boot_s: float = 6.0,
        by_id_dirs: Sequence[str] | None = None,
    ) -> None:
        self.port = port
        self.path = port  # where the device is now (``auto`` resolved; a re-plug may move it)
        self.probe_first = probe_first
        self.line_baud = line_baud or probe_first  # the rate the port is opened at
        self.step_timeout_s = step_timeout_s
        self.flash_timeout_s = flash_timeout_s
        self.goto_config_s = goto_config_s
        self.probe_s = probe_s
        self.boot_s = boot_s
        self.by_id_dirs = by_id_dirs
        self.usb_serial: str | None = None
        self.was_measuring = False  # data frames arrived before the device reached Config
        self._inspecting = False  # ``inspect`` runs: only INSPECTION_REQUESTS may be written
        self._serial: serial.SerialBase | None = None
        self._framer = StreamFramer()
        self._after_reply: list[Frame] = []  # frames that came after the last reply, in the same read
        self._log = LineLog()

    # ---- opening ----------------------------------------

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> Self:
        """Open the port exclusively at ``line_baud`` (DeviceNotFound / DeviceError say what to do)."""
        if self._serial is not None:
            return self
        if self.path == "auto":
            self.path = resolve_port("auto", self.by_id_dirs)
        if not path_exists(self.path):
            raise DeviceNotFound(describe_missing(self.path))
        try:
            self._serial = serial.serial_for_url(
                self.path, self.line_baud, timeout=READ_TIMEOUT_S, exclusive=True
            )
        except serial.SerialException as exc:
            code = getattr(exc, "errno", None)
            if code == errno.ENOENT or "No such file" in str(exc):
                raise DeviceNotFound(describe_missing(self.path)) from None
            raise DeviceError(open_error_message(self.path, exc)) from None
        except ValueError as exc:
            raise InputError(f"cannot open {self.path!r}: {exc}") from None
        self.usb_serial = usb_serial_of(self.path, self.by_id_dirs) or self.usb_serial
        return self

    def close(self) -> None:
        """Close the port (safe to call twice; a vanished device closes quietly)."""
        if self._serial is not None:
            with contextlib.suppress(Exception):
                self._serial.close()
            self._serial = None

    @property
    def is_open(self) -> bool:
        return self._serial is not None

    # ---- low-level I/O ----------------------------------------

    def _port(self) -> serial.SerialBase:
        if self._serial is None:
            raise DeviceError("the port is not open: call open() first")
        return self._serial

    def _read(self) -> bytes:
        """Whatever has arrived (waits up to the port timeout for the first byte)."""
        port = self._port()
        try:
            data = port.read(port.in_waiting or 1)
            if data and port.in_waiting:
                data += port.read(port.in_waiting)
        except (serial.SerialException, OSError) as exc:
            self.close()
            raise DeviceGone(f"{self.path} vanished ({exc}); reconnect() waits for it to come back") from None
        return data

    def _write(self, data: bytes) -> None:
        if self._inspecting and (data[2] not in INSPECTION_REQUESTS or data[3] != 0):
            raise DeviceError(f"refused to write {data.hex(' ')} while inspecting: it may change the device")
        try:
            self._port().write(data)
        except (serial.SerialException, OSError) as exc:
            self.close()
            raise DeviceGone(f"{self.path} vanished while writing ({exc})") from None

    def _exchange(
        self, wanted: set[int], timeout_s: float, resend: bytes | None = None, answer_wakeup: bool = True
    ) -> Frame | None:
        """Frames until one with a MID in ``wanted`` (or Error) arrives; ``resend`` goes out every 0.1 s.

        A WakeUp is answered at once (the device stays in Config only if the ack comes within
        500 ms) unless ``answer_wakeup`` is False; a quiet read confirms a frame the framer holds
        (``StreamFramer.flush``).
        """
        deadline = time.monotonic() + timeout_s
        next_send = 0.0
        while time.monotonic() < deadline:
            if resend is not None and time.monotonic() >= next_send:
                self._write(resend)
                next_send = time.monotonic() + RESEND_S
            data = self._read()
            frames = self._framer.feed(data) if data else self._framer.flush()
            self._log.add(data, frames)
            for i, frame in enumerate(frames):
                if frame.mid == MID.WAKEUP and answer_wakeup and not self._inspecting:
                    self._write(build_frame(MID.WAKEUP_ACK))
                # data, or a WakeUp left unanswered (the device then measures on its own)
                self.was_measuring |= frame.mid in (MID.MTDATA2, MID.MTDATA) or (
                    frame.mid == MID.WAKEUP and self._inspecting
                )
                if frame.mid in wanted or frame.mid == MID.ERROR:
                    self._after_reply = frames[i + 1 :]
                    return frame
        return None

    def request(self, mid: int, payload: bytes = b"", what: str = "") -> Frame:
        """Send one message and return its reply (mid + 1); device errors become DeviceError.

        Flash-writing messages get ``flash_timeout_s``, the others ``step_timeout_s``.
        """
        self._write(build_frame(mid, payload))
        timeout = self.flash_timeout_s if mid in FLASH_WRITES else self.step_timeout_s
        reply = self._exchange({mid + 1}, timeout)
        label = what or MID(mid).name
        if reply is None:
            raise DeviceError(f"no reply to {label} from {self.path} within {timeout:g} s")
        if reply.mid == MID.ERROR:
            code, meaning = parse_error(reply.payload)
            raise DeviceError(f"the device answered {label} with error 0x{code:02X}: {meaning}")
        return reply

    def _set_line(self, baud: int) -> None:
        """Talk at ``baud`` from now on (a fresh framer: bytes at another rate were noise)."""
        self._port().baudrate = baud
        self.line_baud = baud
        self._framer = StreamFramer()
        with contextlib.suppress(serial.SerialException, OSError):
            self._port().reset_input_buffer()

    # ---- hand-shake ----------------------------------------

    def go_to_config(self, rates: Sequence[int] | None = None) -> None:
        """Take the device to Config (see the module docstring); DeviceError says what was tried."""
        acked, rate, tried = self._search_config(rates)
        if not acked:
            self._recover(rate, tried)

    def _search_config(self, rates: Sequence[int] | None) -> tuple[bool, int, list[tuple[int, float]]]:
        """GoToConfig at each rate in turn (nothing else is written): (acknowledged, the rate the line
        is left at: where it was acked, where frames came unanswered, else the likeliest, the rates tried)."""
        rates = list(dict.fromkeys(rates or (self.line_baud, self.probe_first, *SEARCH_BAUDS)))
        main = self.probe_first if self.probe_first in rates else rates[0]  # where the device most likely is
        self._log = LineLog()
        tried: list[tuple[int, float]] = []
        for rate in rates:
            self._set_line(rate)
            frames_before = sum(self._log.frames.values())
            seconds = self.goto_config_s if rate == main else self.probe_s  # a quick look elsewhere
            tried.append((rate, seconds))
            if self._goto_config_for(seconds):
                return True, rate, tried
            if sum(self._log.frames.values()) > frames_before:  # it talks at this rate but ignores us
                return False, rate, tried
        self._set_line(main)
        return False, main, tried

    def _goto_config_for(self, seconds: float) -> bool:
        ack = self._exchange({MID.GOTO_CONFIG_ACK}, seconds, resend=build_frame(MID.GOTO_CONFIG))
        return ack is not None and ack.mid == MID.GOTO_CONFIG_ACK

    def _tried(self, tried: list[tuple[int, float]]) -> str:
        """The GoToConfig search in words: the long look first, then the quick ones."""
        (main, main_s), *others = sorted(tried, key=lambda tried_rate: -tried_rate[1])
        scanned = f", {self.probe_s:g} s at each of {', '.join(str(r) for r, _ in others)}" if others else ""
        return f"GoToConfig for {main_s:g} s at {main} baud{scanned}"

    def _recover(self, rate: int, tried: list[tuple[int, float]]) -> None:
        """Reset, then GoToConfig through the boot (WakeUp answered) until acknowledged."""
        self._write(build_frame(MID.RESET))
        if self._goto_config_for(self.boot_s):
            return
        if not self._log.byte_count:
            hint = f"nothing arrived: check power and cable; {MODEMMANAGER_HINT}"
        elif not self._log.frames:
            hint = "bytes but no Xbus frame at any standard rate: is it an Xsens device, at 8N1?"
        else:
            hint = "the device talks but ignores GoToConfig and Reset: power-cycle it"
        raise DeviceError(
            f"no answer from {self.path}: {self._tried(tried)}, then Reset at {rate} baud and GoToConfig "
            f"for {self.boot_s:g} s (WakeUp {'seen' if self._log.wakeup else 'not seen'}); "
            f"received {self._log.describe()}; {hint}"
        )

    def identify(self) -> tuple[int, str, str]:
        """(device id, product code, firmware) of a device in Config."""
        device_id = parse_device_id(self.request(MID.REQ_DID).payload)
        product = parse_product_code(self.request(MID.REQ_PRODUCT_CODE).payload)
        firmware = parse_fw_rev(self.request(MID.REQ_FW_REV).payload)
        return device_id, product, firmware

    def inspect(self) -> DeviceReport:
        """Read what the device is and how it is set up, changing nothing (docs/protocol.md).

        Only GoToConfig (at each standard rate in turn), the identity and configuration requests
        and, for a device found measuring, GoToMeasurement are written: never Reset, SetBaudrate
        or a flash write (``_write`` refuses anything else while inspecting). A WakeUp is not
        answered (that would hold a booting device in Config): such a device was about to measure,
        and is returned to measurement. A device that does not answer GoToConfig is one line.
        """
        self.open()
        self.was_measuring = False
        self._inspecting = True
        try:
            self._exchange({MID.MTDATA2, MID.MTDATA}, LISTEN_S)  # does it stream before we ask anything?
            acked, _, tried = self._search_config(None)
            if not acked:
                raise DeviceError(
                    f"no answer to GoToConfig from {self.path}: {self._tried(tried)}; received "
                    f"{self._log.describe()}; device info sends no Reset: if it is an Xsens device stuck "
                    f"in measurement, run tankdaq device reset {self.path}"
                )
            report = self._read_setup()
            if self.was_measuring:
                self.request(MID.GOTO_MEASUREMENT)
        finally:
            self._inspecting = False
        return report

    def _read_setup(self) -> DeviceReport:
        """Identity and output configuration of a device in Config (requests only)."""
        device_id, product, firmware = self.identify()
        self._write(build_frame(MID.OUTPUT_CONFIGURATION))  # empty: a request, the configuration stays
        reply = self._exchange({MID.OUTPUT_CONFIGURATION_ACK}, self.step_timeout_s)
        if reply is None:
            raise DeviceError(f"no reply to ReqOutputConfiguration from {self.path}")
        legacy = reply.mid == MID.ERROR
        configuration = () if legacy else tuple(parse_output_configuration(reply.payload))
        return DeviceReport(self.path, self.line_baud, device_id, product, firmware, legacy, configuration,
                            self.was_measuring, self.usb_serial, ftdi_latency_ms(self.path))  # fmt: skip

    def reset_device(self, restore_defaults: bool = False) -> bool:
        """Reset (after RestoreFactoryDefaults if asked); True when the WakeUp of the reboot was seen.

        The WakeUp is not answered, so the device boots into measurement as after power-up.
        """
        self.open()
        self.go_to_config()
        if restore_defaults:
            self.request(MID.RESTORE_FACTORY_DEF)
        self._write(build_frame(MID.RESET))
        self._log = LineLog()
        self._exchange({MID.WAKEUP}, self.boot_s, answer_wakeup=False)
        return self._log.wakeup
