"""The MTi-G driver: open the port, hand-shake, configure the decay outputs, stream samples.

Opening, requests, the hand-shake and inspection are ``device.link.XbusLink``, the base class.

The driver talks to hardware and to ``SimulatedMTi`` the same way: through pyserial on a
path (or a pyserial URL). What it does, in order:

1. open exclusively (``--port auto`` is resolved to the one Xsens device first); remember the
   device's USB serial number, to find it again after a re-plug under another name;
2. take the device to Config (docs/protocol.md has the state machine): GoToConfig every 0.1 s
   (a streaming device may need several), answering a WakeUp within 500 ms; if unanswered, the
   standard baud rates in turn; a device that streams but ignores GoToConfig gets a Reset, and
   GoToConfig goes on through its boot (the field report: acked ~1.7 s after the Reset);
3. read device id, product code and firmware;
4. SetOutputConfiguration for the decay channels, diffing the echoed (effective) configuration
   (each flash write has its own, longer timeout); a device answering Error 0x04 is a 2007-era
   MTi-G and is configured with OutputMode/OutputSettings/Period instead. The orientation is
   negotiated: Euler angles, else (Error 0x21) quaternion, else rotation matrix, else none (an
   IMU-class device, or one its product code says is: roll and pitch from the integrated rate of
   turn, ``device.attitude``); ``info.orientation`` says which, and what was refused;
5. if the line cannot carry the output (or ``baud`` asks for another rate): SetBaudrate (600-series:
   PortConfig), Reset, reopen the port at the new rate and hand-shake again;
6. GoToMeasurement, then yield ``StreamBlock``s: ``SAMPLE_DTYPE`` samples with device time
   from unwrapped SampleTimeFine (legacy: the sample counter times the period), host time
   beside, the raw bytes exactly as received (the recorder stores them) and running counters.

A vanished device (read fails, the pts is gone, or silence) raises ``DeviceGone``;
``reconnect()`` waits for it to come back (at its path, or under a new name with the same USB
serial number) with back-off and configures again.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import DeviceError, DeviceGone, DeviceNotFound, InputError
from ..samples import SAMPLE_DTYPE
from ..xsens.constants import MID, SERIAL_BAUDS
from ..xsens.control import (
    BITS_PER_BYTE,
    ERROR_INVALID_PARAMETER,
    FRAME_OVERHEAD,
    ORIENTATION_OUTPUTS,
    ORIENTATION_WORDS,
    OrientationSource,
    baudrate_payload,
    check_bandwidth,
    decay_output_configuration,
    is_600_series,
    is_imu_class,
    line_refusal,
    output_configuration_payload,
    parse_error,
    parse_output_configuration,
    parse_port_config,
    port_config_payload,
    slowest_baud_carrying,
)
from ..xsens.frame import Frame, build_frame
from ..xsens.mtdata2 import describe_xdi
from ..xsens.timebase import TICKS_PER_SECOND, CounterTracker
from .attitude import MIN_RATE_HZ
from .decoding import SampleDecoder
from .legacy_output import LegacyOutput
from .link import READ_TIMEOUT_S, XbusLink
from .ports import find_by_serial, path_exists
from .read_process import ReadProcess

ERROR_NOT_IMPLEMENTED = 0x04
#: How long a baud move waits for the Reset ack before reopening (it comes at once, if it can be read).
RESET_ACK_WAIT_S = 0.2
#: Share of a line's bit rate the data may use (acks and bursts need the rest).
HEADROOM = 0.9
#: How long a streaming device may send nothing before it is taken for gone (unplugged, powered off).
SILENCE_TIMEOUT_S = 3.0


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
    baud_changed_from: int | None = None  # the device's rate before tankdaq moved it
    usb_serial: str | None = None
    orientation: OrientationSource = field(default_factory=OrientationSource)  # roll and pitch from what

    def describe(self) -> str:
        kind = "legacy MTData" if self.legacy else "MTData2"
        moved = f" (moved from {self.baud_changed_from})" if self.baud_changed_from else ""
        return (
            f"{self.product_code} id {self.device_id:08X} fw {self.firmware} on {self.port} "
            f"at {self.baud} baud{moved}, {self.rate_hz:g} Hz {kind}"
        )


@dataclass
class StreamCounters:
    """Running totals a person (and a test) checks: is anything being lost?"""

    bytes: int = 0
    frames: int = 0
    samples: int = 0
    bad_frames: int = 0  # bad checksums + malformed messages
    bad_checksums: int = 0
    skipped_bytes: int = 0
    false_syncs: int = 0  # checksum-valid false frames the framer turned away
    gaps: int = 0  # PacketCounter jumps
    lost: int = 0  # packets missing in those jumps
    device_errors: list[tuple[int, str]] = field(default_factory=list)

    def metadata(self) -> dict[str, object]:
        """The link counters a recording keeps (names prefixed ``link_``)."""
        names = ("bytes", "frames", "bad_checksums", "skipped_bytes", "false_syncs", "gaps", "lost")
        return {f"link_{name}": getattr(self, name) for name in names}


@dataclass
class StreamBlock:
    """One read from the port: the samples it completed, the raw bytes, and when they arrived. The decay
    pipeline is fed these as they are (``acquire.pipeline``), as is replay with a file's."""

    samples: np.ndarray
    raw: bytes
    host_t: float
    carried: int = 0  # leading samples whose bytes came in earlier reads (a frame held for its successor)
    frames: int = 0  # the frames decoded from ``raw`` (the link's count)


class MTiDriver(XbusLink):
    """Xsens MTi-G over a serial port (path, pyserial URL or ``auto``); see the module docstring.

    ``baud``: the line rate to run at (None: keep the device's rate if it carries the output,
    else move it to the slowest standard rate that does). ``probe_first``: where to look for the
    device first when ``baud`` is None (factory default 115200). ``modulus``: the SampleTimeFine
    modulus (None: the one of the device family the device says it is, reference §2.6).
    """

    def __init__(
        self,
        port: str,
        baud: int | None = None,
        rate_hz: float = 100,
        *,
        probe_first: int = 115200,
        step_timeout_s: float = 1.0,
        flash_timeout_s: float = 3.0,
        goto_config_s: float = 2.0,
        probe_s: float = 0.6,
        boot_s: float = 6.0,
        silence_timeout_s: float = SILENCE_TIMEOUT_S,
        modulus: int | None = None,
        by_id_dirs: Sequence[str] | None = None,
    ) -> None:
        for rate in (baud, probe_first):
            if rate is not None and rate not in SERIAL_BAUDS:
                raise InputError(f"baud {rate} is not an MTi serial rate; use one of {list(SERIAL_BAUDS)}")
        if not (rate_hz > 0 and TICKS_PER_SECOND % rate_hz == 0 and rate_hz <= 400):
            raise InputError(
                f"rate {rate_hz:g} Hz is not an MTi output rate; use a divisor of 400 Hz (100, 200, 400)"
            )
        super().__init__(
            port,
            probe_first=probe_first,
            line_baud=baud,
            step_timeout_s=step_timeout_s,
            flash_timeout_s=flash_timeout_s,
            goto_config_s=goto_config_s,
            probe_s=probe_s,
            boot_s=boot_s,
            by_id_dirs=by_id_dirs,
        )
        self.baud = baud
        self.rate_hz = float(rate_hz)
        self.silence_timeout_s = silence_timeout_s
        self.modulus = modulus
        self.info: DeviceInfo | None = None
        self.counters = StreamCounters()
        self._unread = b""  # the stream's first bytes, read with GoToMeasurement's ack
        self._reset_stream_state()

    def _reset_stream_state(
        self, legacy: LegacyOutput | None = None, product: str = "", integrated: bool = False
    ) -> None:
        # one decoder for the whole session: its unwrapper carries every clock wrap from the first sample
        if self.modulus is None:
            self._samples = SampleDecoder.for_device(product, legacy, integrated)
        else:
            self._samples = SampleDecoder(legacy, self.modulus, integrated)
        self._tracker = CounterTracker()
        self._carry: StreamBlock | None = None
        self._gone: DeviceGone | None = None  # raised at the next read, after the stream's last samples

    # ---- configuration ----------------------------------------

    def configure(self) -> DeviceInfo:
        """Hand-shake, configure the decay outputs and the baud rate; the device is measuring afterwards."""
        self.open()
        self.go_to_config()
        device_id, product, firmware = self.identify()
        configuration, legacy, bits_per_second, orientation = self._configure_outputs(product)
        if orientation.integrated and self.rate_hz < MIN_RATE_HZ:
            raise InputError(
                f"{product} gives no orientation: roll and pitch are integrated from its rate of turn, "
                f"which needs at least {MIN_RATE_HZ:g} Hz; use --rate 100"
            )
        target = self._choose_baud(bits_per_second)
        found = self.line_baud
        if target != found:
            self.move_baud(target, is_600_series(product))
        self.request(MID.GOTO_MEASUREMENT)
        self._reset_stream_state(
            LegacyOutput.for_decay(self.rate_hz) if legacy else None, product, orientation.integrated
        )
        # a device streams at once: what came with the ack is the stream's start, not hand-shake noise
        self._unread = b"".join(f.to_bytes() for f in self._after_reply) + self._framer.take_pending()
        self.counters = StreamCounters()
        self._last_data = time.monotonic()
        self.info = DeviceInfo(self.path, self.line_baud, device_id, product, firmware, legacy, self.rate_hz,
                               tuple(configuration), found if target != found else None,
                               self.usb_serial, orientation)  # fmt: skip
        return self.info

    def _choose_baud(self, bits_per_second: float) -> int:
        """The line rate to measure at: ``baud`` if given (and it carries the data), else the current
        one if it does, else the slowest standard rate that does; refused with the numbers otherwise."""
        wanted = self.baud or self.line_baud
        refusal = line_refusal(bits_per_second, self.rate_hz, wanted, HEADROOM)
        if refusal is None:
            return wanted
        slowest = slowest_baud_carrying(bits_per_second, HEADROOM)
        if self.baud is None and slowest is not None:
            return slowest
        raise InputError(refusal)

    def move_baud(self, target: int, family_600: bool) -> None:
        """SetBaudrate (600-series: PortConfig), Reset, reopen at ``target`` and hand-shake again."""
        old = self.line_baud
        if family_600:
            words = parse_port_config(self.request(MID.PORT_CONFIG, what="ReqPortConfig").payload)
            self.request(MID.SET_PORT_CONFIG, port_config_payload(words, target), "SetPortConfig")
        else:
            self.request(MID.SET_BAUDRATE, baudrate_payload(target), "SetBaudrate")
        # The new rate applies after a reset. Its ack comes at the old rate, the WakeUp at the new
        # one: the boot is looked after by the hand-shake below, the ack only waited for briefly.
        self._write(build_frame(MID.RESET))
        self._exchange({MID.RESET_ACK}, RESET_ACK_WAIT_S)
        self.close()
        self.line_baud = target
        self.open()
        try:
            self.go_to_config([target])
        except DeviceError as exc:
            raise DeviceError(f"moved from {old} to {target} baud, then lost the device: {exc}") from None

    def _configure_outputs(
        self, product: str
    ) -> tuple[list[tuple[int, int]], bool, float, OrientationSource]:
        """(configuration, legacy?, bits/s it needs, orientation source): MTData2 with the first
        orientation output the device accepts (Euler angles, quaternion, rotation matrix; an IMU-class
        product or a device refusing all three: none, the rate of turn is integrated), or the legacy
        settings if the device does not know SetOutputConfiguration."""
        imu_class = is_imu_class(product)
        candidates = [*(() if imu_class else ORIENTATION_OUTPUTS), None]
        refused: list[tuple[str, int]] = []
        while True:  # each refusal moves to the next candidate; the last one (None) returns or raises
            orientation = candidates[len(refused)]
            requested = decay_output_configuration(int(self.rate_hz), orientation=orientation)
            reply = self._set_output_configuration(requested)
            if reply.mid != MID.ERROR:
                source = OrientationSource(orientation, tuple(refused), imu_class)
                echoed = self._check_echo(requested, reply.payload)
                return echoed, False, self._bits_per_second(requested), source
            code, meaning = parse_error(reply.payload)
            if code == ERROR_NOT_IMPLEMENTED and orientation == ORIENTATION_OUTPUTS[0]:
                return [], True, self._configure_legacy(), OrientationSource()
            if code != ERROR_INVALID_PARAMETER or orientation is None:
                asked = "no orientation" if orientation is None else ORIENTATION_WORDS[orientation]
                raise DeviceError(
                    f"the device refused the output configuration (with {asked}): "
                    f"error 0x{code:02X}: {meaning}"
                )
            refused.append((orientation, code))

    def _set_output_configuration(self, requested: list[tuple[int, int]]) -> Frame:
        """SetOutputConfiguration: the device's ack (the effective configuration) or its Error."""
        self._write(build_frame(MID.OUTPUT_CONFIGURATION, output_configuration_payload(requested)))
        reply = self._exchange({MID.OUTPUT_CONFIGURATION_ACK}, self.flash_timeout_s)
        if reply is None:
            raise DeviceError(
                f"no reply to SetOutputConfiguration from {self.path} within {self.flash_timeout_s:g} s"
            )
        return reply

    def _configure_legacy(self) -> float:
        """A 2007-era MTi-G: OutputMode, OutputSettings and Period; the bits/s its MTData needs."""
        output = LegacyOutput.for_decay(self.rate_hz)
        self.request(MID.OUTPUT_MODE, output.mode.to_bytes(2, "big"), "SetOutputMode")
        self.request(MID.OUTPUT_SETTINGS, output.settings.to_bytes(4, "big"), "SetOutputSettings")
        self.request(MID.PERIOD, output.period.to_bytes(2, "big"), "SetPeriod")
        return (output.layout.length + FRAME_OVERHEAD) * self.rate_hz * BITS_PER_BYTE

    @staticmethod
    def _check_echo(requested: list[tuple[int, int]], payload: bytes) -> list[tuple[int, int]]:
        """The echoed (effective) configuration, which must hold every output asked for."""
        echoed = parse_output_configuration(payload)
        differences = [f"{describe_xdi(xdi)} at {hz} Hz" for xdi, hz in requested if (xdi, hz) not in echoed]
        if differences:
            got = ", ".join(f"{describe_xdi(x)} {h} Hz" for x, h in echoed)
            raise DeviceError(f"the device did not accept {'; '.join(differences)} (it will send: {got})")
        return echoed

    def _bits_per_second(self, requested: list[tuple[int, int]]) -> float:
        return check_bandwidth(requested, self.rate_hz, self.line_baud).bits_per_second

    # ---- streaming ----------------------------------------

    def closing_metadata(self) -> dict[str, object]:
        """What a recording keeps at close: the link counters, and an integrated attitude's gyro bias."""
        return {**self.counters.metadata(), **self._samples.attitude_metadata()}

    def read_block(self) -> StreamBlock:
        """One read: the samples it completed (maybe none). Raises DeviceGone if the device vanished;
        a frame the decoder held for confirmation is given first (the stream ended: ``finish``)."""
        self._raise_if_gone()
        try:
            raw = self._read()
        except DeviceGone as exc:
            return self._end_of_stream(exc)
        return self._block_of(raw, time.time(), time.monotonic())

    def reads_in_process(self, stop: threading.Event, interval_s: float) -> Iterator[StreamBlock]:
        """The blocks of reads made every ``interval_s`` by a process of their own (``ReadProcess`` on
        the port's descriptor), stamped there, until ``stop`` is set (then every byte it read comes out)
        or the device is gone (DeviceGone, after the last block, as ``read_block``). The port must be a
        path (``reads_in_process_possible``)."""
        with ReadProcess(self._port().fileno(), interval_s, READ_TIMEOUT_S) as process:
            for chunk in process.chunks(stop):
                if chunk.gone is not None:
                    self.close()
                    why = f"{self.path} vanished ({chunk.gone}); reconnect() waits for it to come back"
                    yield self._end_of_stream(DeviceGone(why))
                else:
                    yield self._block_of(chunk.data, chunk.host_t, chunk.monotonic_s)
                self._raise_if_gone()
            if not process.stopping:  # it ended on its own: killed, or a bug
                self.close()
                yield self._end_of_stream(DeviceGone(f"the reader process of {self.path} ended "
                                                     f"({process.exit_note()})"))  # fmt: skip
                self._raise_if_gone()

    @property
    def reads_in_process_possible(self) -> bool:
        """Whether the port is a descriptor a reader process can share (a path, not a pyserial URL)."""
        return self._serial is not None and "://" not in self.path and self._serial.fileno() >= 0

    def _raise_if_gone(self) -> None:
        if self._gone is not None:
            gone, self._gone = self._gone, None
            raise gone

    def _block_of(self, raw: bytes, host_t: float, now: float) -> StreamBlock:
        """The block of one read: ``raw`` arrived at ``host_t`` (wall clock), ``now`` (monotonic)."""
        if self._unread:
            raw, self._unread = self._unread + raw, b""
        if raw:
            self._last_data = now
        elif now - self._last_data > self.silence_timeout_s:
            self.close()
            return self._end_of_stream(
                DeviceGone(
                    f"no data from {self.path} for {self.silence_timeout_s:g} s "
                    "(cable unplugged or device powered off?)"
                )
            )
        samples, decoded = self._samples.feed(raw, host_t)
        for frame in decoded.other_frames:
            if frame.mid == MID.ERROR:
                self.counters.device_errors.append(parse_error(frame.payload))
        self._count(raw, decoded.frames, samples)
        return StreamBlock(samples, raw, host_t, min(decoded.carried, samples.size), decoded.frames)

    def _end_of_stream(self, gone: DeviceGone) -> StreamBlock:
        """The stream ended: the frames the decoder still holds whose structure confirms them come out as a
        last block (their bytes were in earlier blocks' raw), and ``gone`` is raised at the next read."""
        host_t = time.time()
        samples, decoded = self._samples.finish(host_t)
        if not samples.size:
            raise gone
        self._gone = gone
        self._count(b"", decoded.frames, samples)
        return StreamBlock(samples, b"", host_t, samples.size, decoded.frames)

    def _count(self, raw: bytes, frames: int, samples: np.ndarray) -> None:
        c, d = self.counters, self._samples.stream
        c.bytes += len(raw)
        c.frames += frames
        c.samples += samples.size
        c.bad_frames = d.bad_checksums + d.malformed
        c.bad_checksums, c.skipped_bytes, c.false_syncs = d.bad_checksums, d.skipped_bytes, d.false_syncs
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
                self._carry = StreamBlock(block.samples[keep:], b"", block.host_t)
                block = StreamBlock(block.samples[:keep], block.raw, block.host_t, frames=block.frames)
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

    def _where_now(self) -> str | None:
        """The device's path now: where it was, or where its USB serial number turned up after a re-plug."""
        if path_exists(self.path):
            return self.path
        return find_by_serial(self.usb_serial, self.by_id_dirs) if self.usb_serial else None

    def reconnect(
        self, timeout_s: float = 30.0, first_delay_s: float = 0.05, max_delay_s: float = 1.0
    ) -> DeviceInfo:
        """Wait for the device to come back (back-off doubling up to ``max_delay_s``) and configure again."""
        self.close()
        deadline = time.monotonic() + timeout_s
        delay = first_delay_s
        last_error = "the port did not reappear"
        while True:
            path = self._where_now()
            if path is not None:
                self.path = path
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
                serial_note = f" (USB serial {self.usb_serial})" if self.usb_serial else ""
                raise DeviceGone(
                    f"{self.port}{serial_note} did not come back within {timeout_s:g} s ({last_error})"
                )
            time.sleep(min(delay, remaining))
            delay = min(delay * 2, max_delay_s)
