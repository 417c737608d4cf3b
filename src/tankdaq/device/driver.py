"""The MTi-G driver: open the port, hand-shake, configure the decay outputs, stream samples.

The driver talks to hardware and to ``SimulatedMTi`` the same way: through pyserial on a
path (or a pyserial URL). What it does, in order:

1. open exclusively (a second program on the port gets a clear "busy" error);
2. take the device to Config (GoToConfig repeated: it may be streaming; WakeUp answered);
3. read device id, product code and firmware;
4. check the output rate fits the baud rate, then SetOutputConfiguration for the decay
   channels and diff the echoed (effective) configuration; a device answering Error 0x04 is
   a 2007-era MTi-G and is configured with OutputMode/OutputSettings/Period instead;
5. GoToMeasurement, then yield ``StreamBlock``s: ``SAMPLE_DTYPE`` samples with device time
   from unwrapped SampleTimeFine (legacy: the sample counter times the period), host time
   beside, the raw bytes exactly as received (the recorder stores them) and running counters.

A vanished device (read fails, the pts is gone, or silence) raises ``DeviceGone``;
``reconnect()`` waits for the path to come back with back-off and configures again.
"""

from __future__ import annotations

import contextlib
import errno
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import serial

from ..errors import DeviceError, DeviceGone, DeviceNotFound, InputError
from ..samples import SAMPLE_DTYPE
from ..xsens.constants import BAUD_CODES, MID
from ..xsens.control import (
    BITS_PER_BYTE,
    FRAME_OVERHEAD,
    check_bandwidth,
    decay_output_configuration,
    output_configuration_payload,
    parse_device_id,
    parse_error,
    parse_fw_rev,
    parse_output_configuration,
    parse_product_code,
)
from ..xsens.frame import Frame, build_frame
from ..xsens.framer import StreamFramer
from ..xsens.mtdata2 import describe_xdi
from ..xsens.timebase import MODULUS_ONE_DAY, TICKS_PER_SECOND, CounterTracker
from .decoding import SampleDecoder
from .legacy_output import LegacyOutput
from .ports import describe_missing, path_exists

#: Baud rates tried by ``scan_baud`` (most common first).
SCAN_BAUDS = (115200, 460800, 921600, 230400, 57600, 38400, 19200, 9600)
ERROR_NOT_IMPLEMENTED = 0x04


@dataclass(frozen=True)
class DeviceInfo:
    """What the hand-shake learned."""

    port: str
    baud: int
    device_id: int
    product_code: str
    firmware: str
    legacy: bool
    rate_hz: float
    configuration: tuple[tuple[int, int], ...] = ()

    def describe(self) -> str:
        kind = "legacy MTData" if self.legacy else "MTData2"
        return (
            f"{self.product_code} id {self.device_id:08X} fw {self.firmware} on {self.port} "
            f"at {self.baud} baud, {self.rate_hz:g} Hz {kind}"
        )


@dataclass
class StreamCounters:
    """Running totals a person (and a test) checks: is anything being lost?"""

    bytes: int = 0
    frames: int = 0
    samples: int = 0
    bad_frames: int = 0  # bad checksums + malformed messages
    skipped_bytes: int = 0
    gaps: int = 0  # PacketCounter jumps
    lost: int = 0  # packets missing in those jumps
    device_errors: list[tuple[int, str]] = field(default_factory=list)


@dataclass
class StreamBlock:
    """One read from the port: the samples it completed, the raw bytes, and when they arrived."""

    samples: np.ndarray
    raw: bytes
    host_t: float
    frames: int


class MTiDriver:
    """Xsens MTi-G over a serial port (path or pyserial URL); see the module docstring."""

    def __init__(
        self,
        port: str,
        baud: int = 115200,
        rate_hz: float = 100,
        *,
        reply_timeout_s: float = 1.0,
        config_attempts: int = 20,
        silence_timeout_s: float = 3.0,
        scan_baud: bool = False,
        modulus: int = MODULUS_ONE_DAY,
    ) -> None:
        if baud not in BAUD_CODES.values():
            raise InputError(f"baud {baud} is not an MTi rate; use one of {sorted(set(BAUD_CODES.values()))}")
        if not (rate_hz > 0 and TICKS_PER_SECOND % rate_hz == 0 and rate_hz <= 400):
            raise InputError(
                f"rate {rate_hz:g} Hz is not an MTi output rate; use a divisor of 400 Hz (100, 200, 400)"
            )
        self.port = port
        self.baud = baud
        self.rate_hz = float(rate_hz)
        self.reply_timeout_s = reply_timeout_s
        self.config_attempts = config_attempts
        self.silence_timeout_s = silence_timeout_s
        self.scan_baud = scan_baud
        self.modulus = modulus
        self.info: DeviceInfo | None = None
        self.counters = StreamCounters()
        self._serial: serial.SerialBase | None = None
        self._framer = StreamFramer()
        self._reset_stream_state()

    def _reset_stream_state(self, legacy: LegacyOutput | None = None) -> None:
        self._samples = SampleDecoder(legacy, self.modulus)
        self._tracker = CounterTracker()
        self._carry: StreamBlock | None = None

    # ---- opening ----------------------------------------

    def __enter__(self) -> MTiDriver:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> MTiDriver:
        """Open the port exclusively at ``baud`` (raises DeviceNotFound / DeviceError with what to do)."""
        if self._serial is not None:
            return self
        if not path_exists(self.port):
            raise DeviceNotFound(describe_missing(self.port))
        try:
            self._serial = serial.serial_for_url(self.port, self.baud, timeout=0.05, exclusive=True)
        except serial.SerialException as exc:
            raise self._open_error(exc) from None
        except ValueError as exc:
            raise InputError(f"cannot open {self.port!r}: {exc}") from None
        return self

    def _open_error(self, exc: serial.SerialException) -> DeviceError:
        code = getattr(exc, "errno", None)
        text = str(exc)
        if code == errno.ENOENT or "No such file" in text:
            return DeviceNotFound(describe_missing(self.port))
        if code in (errno.EAGAIN, errno.EBUSY) or "exclusively lock" in text:
            return DeviceError(
                f"port {self.port} is busy: another program has it open "
                "(tankdaq record? a terminal? ModemManager?)"
            )
        if code == errno.EACCES:
            return DeviceError(
                f"no permission to open {self.port}: add yourself to the 'dialout' group, log in again"
            )
        return DeviceError(f"cannot open {self.port}: {text}")

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
            raise DeviceGone(f"{self.port} vanished ({exc}); reconnect() waits for it to come back") from None
        return data

    def _write(self, data: bytes) -> None:
        try:
            self._port().write(data)
        except (serial.SerialException, OSError) as exc:
            self.close()
            raise DeviceGone(f"{self.port} vanished while writing ({exc})") from None

    def _frames_until(self, wanted: set[int], timeout_s: float, resend: bytes | None = None) -> Frame | None:
        """Frames until one with a MID in ``wanted`` (or Error) arrives; ``resend`` goes out every 0.1 s."""
        deadline = time.monotonic() + timeout_s
        next_send = 0.0
        while time.monotonic() < deadline:
            if resend is not None and time.monotonic() >= next_send:
                self._write(resend)
                next_send = time.monotonic() + 0.1
            for frame in self._framer.feed(self._read()):
                if frame.mid == MID.WAKEUP:
                    self._write(build_frame(MID.WAKEUP_ACK))
                if frame.mid in wanted or frame.mid == MID.ERROR:
                    return frame
        return None

    def request(self, mid: int, payload: bytes = b"", what: str = "") -> Frame:
        """Send one message and return its reply (mid + 1); device errors become DeviceError."""
        self._write(build_frame(mid, payload))
        reply = self._frames_until({mid + 1}, self.reply_timeout_s)
        label = what or MID(mid).name
        if reply is None:
            raise DeviceError(f"no reply to {label} from {self.port} within {self.reply_timeout_s:g} s")
        if reply.mid == MID.ERROR:
            code, meaning = parse_error(reply.payload)
            raise DeviceError(f"the device answered {label} with error 0x{code:02X}: {meaning}")
        return reply

    # ---- hand-shake and configuration ----------------------------------------

    def go_to_config(self) -> None:
        """GoToConfig until acknowledged (a streaming device may need several tries)."""
        self._framer = StreamFramer()
        with contextlib.suppress(serial.SerialException, OSError):
            self._port().reset_input_buffer()
        ack = self._frames_until(
            {MID.GOTO_CONFIG_ACK}, self.config_attempts * 0.1, resend=build_frame(MID.GOTO_CONFIG)
        )
        if ack is not None and ack.mid == MID.GOTO_CONFIG_ACK:
            return
        others = ", ".join(str(b) for b in SCAN_BAUDS if b != self.baud)
        seen = "garbage only" if self._framer.frames == 0 and self._framer.skipped_bytes else "nothing"
        raise DeviceError(
            f"no answer from {self.port} at {self.baud} baud ({seen} received): check power and cable, "
            f"or try another --baud ({others}) or --scan-baud"
        )

    def configure(self) -> DeviceInfo:
        """Hand-shake and configure the decay outputs; the device is measuring afterwards."""
        self.open()
        if self.scan_baud:
            self._find_baud()
        else:
            self.go_to_config()
        device_id = parse_device_id(self.request(MID.REQ_DID).payload)
        product = parse_product_code(self.request(MID.REQ_PRODUCT_CODE).payload)
        firmware = parse_fw_rev(self.request(MID.REQ_FW_REV).payload)
        configuration, legacy = self._configure_outputs()
        self.request(MID.GOTO_MEASUREMENT)
        self._reset_stream_state(LegacyOutput.for_decay(self.rate_hz) if legacy else None)
        self.counters = StreamCounters()
        self._last_data = time.monotonic()
        self.info = DeviceInfo(self.port, self.baud, device_id, product, firmware, legacy, self.rate_hz,
                               tuple(configuration))  # fmt: skip
        return self.info

    def _find_baud(self) -> None:
        """Try the standard baud rates until the device answers GoToConfig."""
        for baud in dict.fromkeys((self.baud, *SCAN_BAUDS)):
            self._port().baudrate = baud
            self.baud = baud
            with contextlib.suppress(DeviceError):
                self.go_to_config()
                return
        raise DeviceError(f"no answer from {self.port} at any of {', '.join(map(str, SCAN_BAUDS))} baud")

    def _configure_outputs(self) -> tuple[list[tuple[int, int]], bool]:
        """MTData2 output configuration, or the legacy settings if the device does not know it."""
        requested = decay_output_configuration(int(self.rate_hz))
        budget = check_bandwidth(requested, self.rate_hz, self.baud)
        if not budget.ok:
            raise InputError(self._budget_message(budget.bits_per_second))
        self._write(build_frame(MID.OUTPUT_CONFIGURATION, output_configuration_payload(requested)))
        reply = self._frames_until({MID.OUTPUT_CONFIGURATION_ACK}, self.reply_timeout_s)
        if reply is None:
            raise DeviceError(f"no reply to SetOutputConfiguration from {self.port}")
        if reply.mid == MID.ERROR:
            code, meaning = parse_error(reply.payload)
            if code != ERROR_NOT_IMPLEMENTED:
                raise DeviceError(
                    f"the device refused the output configuration: error 0x{code:02X}: {meaning}"
                )
            self._configure_legacy()
            return [], True
        echoed = parse_output_configuration(reply.payload)
        differences = [f"{describe_xdi(xdi)} at {hz} Hz" for xdi, hz in requested if (xdi, hz) not in echoed]
        if differences:
            got = ", ".join(f"{describe_xdi(x)} {h} Hz" for x, h in echoed)
            raise DeviceError(f"the device did not accept {'; '.join(differences)} (it will send: {got})")
        return echoed, False

    def _budget_message(self, bits_per_second: float) -> str:
        faster = [b for b in sorted(set(BAUD_CODES.values())) if bits_per_second <= 0.9 * b]
        hint = f"use --baud {faster[0]}" if faster else "lower the rate"
        return (
            f"{self.rate_hz:g} Hz needs {bits_per_second / 1000:.1f} kbit/s, {self.baud} baud carries "
            f"{self.baud / 1000:.1f} kbit/s: {hint}"
        )

    def _configure_legacy(self) -> None:
        """2007-era MTi-G: OutputMode, OutputSettings and Period (reference §4)."""
        output = LegacyOutput.for_decay(self.rate_hz)
        bits_per_second = (output.layout.length + FRAME_OVERHEAD) * self.rate_hz * BITS_PER_BYTE
        if bits_per_second > 0.9 * self.baud:
            raise InputError(self._budget_message(bits_per_second))
        self.request(MID.OUTPUT_MODE, output.mode.to_bytes(2, "big"), "SetOutputMode")
        self.request(MID.OUTPUT_SETTINGS, output.settings.to_bytes(4, "big"), "SetOutputSettings")
        self.request(MID.PERIOD, output.period.to_bytes(2, "big"), "SetPeriod")

    # ---- streaming ----------------------------------------

    def read_block(self) -> StreamBlock:
        """One read: the samples it completed (maybe none). Raises DeviceGone if the device vanished."""
        raw = self._read()
        host_t = time.time()
        now = time.monotonic()
        if raw:
            self._last_data = now
        elif now - self._last_data > self.silence_timeout_s:
            self.close()
            raise DeviceGone(
                f"no data from {self.port} for {self.silence_timeout_s:g} s "
                "(cable unplugged or device powered off?)"
            )
        samples, decoded = self._samples.feed(raw, host_t)
        for frame in decoded.other_frames:
            if frame.mid == MID.ERROR:
                self.counters.device_errors.append(parse_error(frame.payload))
        self._count(raw, decoded.frames, samples)
        return StreamBlock(samples, raw, host_t, decoded.frames)

    def _count(self, raw: bytes, frames: int, samples: np.ndarray) -> None:
        c, d = self.counters, self._samples.stream
        c.bytes += len(raw)
        c.frames += frames
        c.samples += samples.size
        c.bad_frames = d.bad_checksums + d.malformed
        c.skipped_bytes = d.skipped_bytes
        if samples.size:
            self._tracker.update_many(samples["counter"])
            c.gaps, c.lost = self._tracker.gap_count, self._tracker.lost

    def stream(
        self, duration_s: float | None = None, max_samples: int | None = None
    ) -> Iterator[StreamBlock]:
        """Blocks with samples until ``duration_s`` of device time or ``max_samples`` (None: for ever).

        The last block is cut at the limit; the samples beyond it come first in the next call
        (their raw bytes went out with the block they arrived in), so nothing read is lost.
        """
        if self.info is None:
            self.configure()
        first_t: float | None = None
        count = 0
        while True:
            block, self._carry = (self._carry, None) if self._carry is not None else (self.read_block(), None)
            if not block.samples.size:
                continue
            if first_t is None:
                first_t = float(block.samples["t"][0])
            keep = block.samples.size
            if duration_s is not None:
                keep = min(keep, int(np.searchsorted(block.samples["t"] - first_t, duration_s - 1e-9)))
            if max_samples is not None:
                keep = min(keep, max_samples - count)
            if keep < block.samples.size:
                self._carry = StreamBlock(block.samples[keep:], b"", block.host_t, 0)
                block = StreamBlock(block.samples[:keep], block.raw, block.host_t, block.frames)
            count += block.samples.size
            if block.samples.size:
                yield block
            if self._carry is not None:
                return

    def samples(self, duration_s: float) -> np.ndarray:
        """Convenience: all samples of the next ``duration_s`` device seconds in one array."""
        blocks = [b.samples for b in self.stream(duration_s=duration_s)]
        return np.concatenate(blocks) if blocks else np.zeros(0, dtype=SAMPLE_DTYPE)

    # ---- reconnecting ----------------------------------------

    def reconnect(
        self, timeout_s: float = 30.0, first_delay_s: float = 0.05, max_delay_s: float = 1.0
    ) -> DeviceInfo:
        """Wait for the port to come back (back-off doubling up to ``max_delay_s``) and configure again."""
        self.close()
        deadline = time.monotonic() + timeout_s
        delay = first_delay_s
        last_error = "the port did not reappear"
        while True:
            if path_exists(self.port):
                try:
                    self.open()
                    return self.configure()
                except (DeviceError, InputError) as exc:
                    if isinstance(exc, InputError) and not isinstance(exc, DeviceNotFound):
                        raise
                    last_error = str(exc)
                    self.close()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DeviceGone(f"{self.port} did not come back within {timeout_s:g} s ({last_error})")
            time.sleep(min(delay, remaining))
            delay = min(delay * 2, max_delay_s)
