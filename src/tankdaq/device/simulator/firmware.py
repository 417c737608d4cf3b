"""The simulated MTi's firmware: the MT messages it answers, its states, and when it sends what.

It answers the configuration messages a driver uses, honours SetOutputConfiguration (outputs,
rates, precision; the ack echoes what it will really send), and speaks the 2007-era MTData
(0x32) protocol when ``legacy``. Frames come from a ``FrameSource`` on the device clock: frame
``k`` is due at the source's time for it (divided by ``speed``) after power-up, or after the
measurement started for a recording, whether or not anyone listens, as on a real MTi. Payloads
are built and parsed by ``tankdaq.xsens`` only.

States a lab meets (``Behaviour``): stuck in measurement, ignoring GoToConfig until a Reset;
slow flash writes; a boot of some seconds after Reset before the WakeUp; a baud rate that
changes only after Reset (the host must reopen at the new rate: the link reads the slave's
termios speed); a 600-series product that sets its baud rate with PortConfig; a device that
refuses some orientation outputs (Error 0x21 to a SetOutputConfiguration holding one), and an
IMU-class product that has none.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...errors import InputError, ProtocolError
from ...xsens.constants import FLASH_WRITES, MID, baud_code
from ...xsens.control import (
    ERROR_INVALID_PARAMETER,
    ORIENTATION_OUTPUTS,
    baudrate_payload,
    device_id_payload,
    output_configuration_payload,
    parse_baudrate,
    parse_output_configuration,
    parse_port_config,
    port_config_baud,
    port_config_payload,
)
from ...xsens.frame import Frame, build_frame
from ...xsens.framer import StreamFramer
from ...xsens.mtdata2 import SPEC_BY_BASE, TYPE_MASK
from .faults import Faults
from .identity import DeviceIdentity
from .output import Output, effective_configuration
from .pty_link import PtyLink
from .sources import FrameSource

#: Answer to the host's WakeUpAck must come within this time after WakeUp, else the device measures.
WAKEUP_WINDOW_S = 0.5
#: The device's frames reach the host in bursts at most this often, every frame due in one write: an FTDI
#: cable's default latency timer (reference: lab-practice.md, "USB latency"). Frame by frame, the loop
#: turned 800 times a second at 8x speed, and a third of the simulator's CPU went on those turns.
BURST_S = 0.016
ERROR_INVALID_MESSAGE = 0x04
ERROR_INVALID_BAUD = 0x20
#: Ports of a 600-series device (PortConfig words): the host port first.
PORTS_600 = 3
FACTORY_BAUD = 115200


@dataclass(frozen=True)
class Behaviour:
    """How the device behaves beyond the protocol's letter (all off: an obliging MTi)."""

    stuck: bool = False  # measuring, it ignores GoToConfig until a Reset (MTi-G-700 field report)
    flash_write_s: float = 0.0  # wall seconds before a flash-writing message is acknowledged
    boot_s: float = 0.0  # wall seconds of silence after a Reset before the WakeUp
    measuring_at_start: bool = False  # powered up before the host came: already streaming
    #: orientation outputs it answers Error 0x21 to (``refused_orientation``; an IMU-class identity: all)
    refuses: frozenset[str] = frozenset()


def refused_outputs(
    behaviour: Behaviour, identity: DeviceIdentity, recorded: list[tuple[int, int]] | None
) -> frozenset[str]:
    """The orientation outputs a device refuses: as it behaves, all of them on an IMU-class product, and
    on a recording's device those the recording does not hold (it can only send what it sent)."""
    refused = set(behaviour.refuses) | set(ORIENTATION_OUTPUTS if identity.imu_class else ())
    if recorded is not None:
        sent = {SPEC_BY_BASE[xdi & TYPE_MASK].name for xdi, _ in recorded if xdi & TYPE_MASK in SPEC_BY_BASE}
        refused |= set(ORIENTATION_OUTPUTS) - sent
    return frozenset(refused)


#: ``tankdaq simulate --refuse`` words for the orientation outputs.
REFUSABLE = {"euler": "EulerAngles", "quaternion": "Quaternion", "matrix": "RotationMatrix"}


def refused_orientation(text: str) -> frozenset[str]:
    """``"euler,quaternion"`` -> the orientation outputs it refuses (``Behaviour.refuses``)."""
    words = [word.strip() for word in text.split(",") if word.strip()]
    unknown = [word for word in words if word not in REFUSABLE]
    if unknown:
        raise InputError(
            f"--refuse {unknown[0]!r} not understood: list orientation outputs among {', '.join(REFUSABLE)}, "
            "e.g. euler or euler,quaternion"
        )
    return frozenset(REFUSABLE[word] for word in words)


@dataclass(frozen=True)
class ReceivedMessage:
    """One message the host wrote, as the device's framer found it."""

    mid: int
    payload: bytes
    heard: bool  # False: it came at another baud rate or during a boot, and the device did not act on it


class Firmware:
    """Device state and message handling; driven by the simulator's thread through ``receive``
    (what the host wrote) and ``tick`` (the clock), sending on ``line``."""

    def __init__(
        self,
        source: FrameSource,
        line: PtyLink,
        *,
        identity: DeviceIdentity,
        behaviour: Behaviour,
        baud: int,
        speed: float,
        legacy: bool,
        faults: Faults,
        seed: int,
    ) -> None:
        self.source = source
        self.line = line
        self.identity = identity
        self.behaviour = behaviour
        self.baud = self.pending_baud = baud
        self.speed = speed
        self.faults = faults
        self.refuses = refused_outputs(behaviour, identity, source.configuration)
        self.output = Output(legacy=legacy, clock_modulus=identity.clock_modulus, lacking=self.refuses)
        self.measuring = False
        self._rng = np.random.default_rng([seed, 99])
        self._epoch = time.monotonic()
        self._origin_s = 0.0  # device time of the source's frame 0
        self._rolling = False  # a recording started playing since power-up
        self._next_frame = 0
        self._stalled = (0, 0)  # frame indices [first, stop) that are never sent
        self._outbox = bytearray()
        self._framer = StreamFramer()
        self._wakeup_sent_at: float | None = None
        self._last_burst = -math.inf  # when frames were last made (BURST_S)
        self._booting_until: float | None = None
        self._stuck = False
        # counters people and tests look at
        self.frames_sent = 0
        self.bytes_corrupted = 0
        self.bytes_dropped = 0
        self.received: list[ReceivedMessage] = []  # every message the host wrote, heard or not

    @property
    def commands_seen(self) -> list[int]:
        """The message ids the device heard and acted on, in order."""
        return [message.mid for message in self.received if message.heard]

    # ---- power and clock ----------------------------------------

    def power_up(self, boot_s: float = 0.0) -> None:
        """Boot: the clock restarts, the stored configuration stays (it lives in flash), a pending baud
        rate takes effect, and after ``boot_s`` of silence the WakeUp goes out."""
        self._epoch = time.monotonic()
        self._origin_s = 0.0
        self._rolling = False
        self._next_frame = 0
        self._outbox.clear()
        self._framer = StreamFramer()
        self.baud = self.pending_baud
        self.measuring = False
        self._stuck = False
        self._wakeup_sent_at = None
        self._booting_until = time.monotonic() + boot_s
        self._finish_boot()

    def already_measuring(self) -> None:
        """Powered long before the host came: no WakeUp, streaming (and stuck, if so behaved)."""
        self._outbox.clear()
        self._wakeup_sent_at = None
        self._start_measuring()
        self._stuck = self.behaviour.stuck

    def device_time(self) -> float:
        """Seconds on the device clock since power-up."""
        return (time.monotonic() - self._epoch) * self.speed

    def _finish_boot(self) -> None:
        if self._booting_until is not None and time.monotonic() >= self._booting_until:
            self._booting_until = None
            self._send(build_frame(MID.WAKEUP))
            self._wakeup_sent_at = time.monotonic()

    def tick(self) -> None:
        """What the clock brings: the end of a boot, a WakeUp left unanswered."""
        self._finish_boot()
        if self._wakeup_sent_at is not None and time.monotonic() - self._wakeup_sent_at > WAKEUP_WINDOW_S:
            self._wakeup_sent_at = None  # no WakeUpAck: the device starts measuring on its own
            self._start_measuring()

    def send_due(self) -> None:
        """Queue the frames due by now and send what the line carries."""
        self._produce_frames()
        self.flush()

    def next_due_s(self) -> float:
        """Wall seconds until ``tick`` has something to do (at most 20 ms)."""
        if self._booting_until is not None:
            return min(0.02, max(0.0, self._booting_until - time.monotonic()))
        if not self.measuring:
            return 0.02
        device_s = self._origin_s + self.source.time_s(self._next_frame, self.output)
        now = time.monotonic()
        due = min(0.02, max(0.0, self._epoch + device_s / self.speed - now, self._last_burst + BURST_S - now))
        return min(due, self.line.holding(self._latency_s)) if self._outbox else due

    @property
    def _latency_s(self) -> float:
        return self.faults.latency_ms / 1000

    @property
    def has_output(self) -> bool:
        """Bytes wait and the line would take them now (a USB latency burst is not held back)."""
        return bool(self._outbox) and self.line.holding(self._latency_s) == 0

    def flush(self) -> None:
        """Send what the baud rate allows since the last write (the pty itself has no speed)."""
        self.line.send(self._outbox, self.baud, self.speed, self._latency_s)

    # ---- messages ----------------------------------------

    def receive(self, data: bytes) -> None:
        """Bytes the host wrote: whole commands are logged (``received``) and handled in order.

        At the wrong baud rate the device sees noise and while booting it hears nothing: those
        messages are logged as not heard (the log is what the host sent, for tests to check)."""
        in_tune = self.line.speed_matches(self.baud)
        for frame in self._framer.feed(data) + self._framer.flush():  # a host writes whole commands
            heard = in_tune and self._booting_until is None  # after a Reset among them: a rebooting device
            self.received.append(ReceivedMessage(frame.mid, frame.payload, heard))
            if heard:
                self._handle(frame)

    def _reply(self, mid: int, payload: bytes = b"") -> None:
        self._send(build_frame(mid, payload))

    def _error(self, code: int) -> None:
        self._reply(MID.ERROR, bytes((code,)))

    def _handle(self, frame: Frame) -> None:
        mid, data = frame.mid, frame.payload
        if mid == MID.WAKEUP_ACK:
            self._wakeup_sent_at = None
            return
        if mid == MID.GOTO_CONFIG:
            if self._stuck:
                return  # the field report's MTi-G-700: only a Reset gets through
            self._wakeup_sent_at = None
            self.measuring = False
            self._reply(MID.GOTO_CONFIG_ACK)
            return
        if mid == MID.RESET:
            self._reply(MID.RESET_ACK)
            self.flush()
            self.power_up(self.behaviour.boot_s)
            return
        if self.measuring:
            return  # a measuring device ignores all but GoToConfig and Reset
        handlers: dict[int, Callable[[bytes], None]] = {
            MID.GOTO_MEASUREMENT: self._on_goto_measurement,
            MID.REQ_DID: lambda _: self._reply(
                MID.DEVICE_ID, device_id_payload(self.identity.device_id, self.identity.family_600)
            ),
            MID.REQ_PRODUCT_CODE: lambda _: self._reply(
                MID.PRODUCT_CODE, self.identity.product_code.encode()
            ),
            MID.REQ_FW_REV: lambda _: self._reply(MID.FW_REV, self.identity.firmware),
            MID.REQ_BAUDRATE: self._on_baudrate,
            MID.RESTORE_FACTORY_DEF: self._on_restore_defaults,
        }
        handlers.update(self._legacy_handlers() if self.output.legacy else self._mkiv_handlers())
        if self.identity.family_600:
            handlers[MID.PORT_CONFIG] = self._on_port_config
            del handlers[MID.REQ_BAUDRATE]  # 600-series: PortConfig instead
        handler = handlers.get(mid)
        if handler is None:
            self._error(ERROR_INVALID_MESSAGE)
            return
        if (data and mid in FLASH_WRITES) or mid == MID.RESTORE_FACTORY_DEF:
            time.sleep(self.behaviour.flash_write_s)  # writing flash: nothing else happens meanwhile
        handler(data)

    def _mkiv_handlers(self) -> dict[int, Callable[[bytes], None]]:
        return {MID.OUTPUT_CONFIGURATION: self._on_output_configuration}

    def _legacy_handlers(self) -> dict[int, Callable[[bytes], None]]:
        def setter(name: str, fmt: str, ack: int) -> Callable[[bytes], None]:
            def handle(data: bytes) -> None:
                if data:
                    try:
                        (value,) = struct.unpack(fmt, data)
                        mode = dataclasses.replace(self.output.legacy_mode, **{name: value})
                    except (struct.error, ValueError):
                        self._error(ERROR_INVALID_PARAMETER)
                        return
                    self.output.legacy_mode = mode
                    self._reply(ack)
                else:
                    self._reply(ack, struct.pack(fmt, getattr(self.output.legacy_mode, name)))

            return handle

        return {
            MID.OUTPUT_MODE: setter("mode", ">H", MID.OUTPUT_MODE_ACK),
            MID.OUTPUT_SETTINGS: setter("settings", ">I", MID.OUTPUT_SETTINGS_ACK),
            MID.PERIOD: setter("period", ">H", MID.PERIOD_ACK),
        }

    def _on_restore_defaults(self, _: bytes) -> None:
        """Factory settings (output, legacy mode, 115200 baud) apply from the next power-up."""
        self.output.restore_defaults()
        self.pending_baud = FACTORY_BAUD
        self._reply(MID.RESTORE_FACTORY_DEF_ACK)

    def _on_port_config(self, data: bytes) -> None:
        """600-series: one U32 per port, the baud code in the low byte; applies after a reset."""
        if not data:
            others = [baud_code(FACTORY_BAUD)] * (PORTS_600 - 1)
            self._reply(MID.PORT_CONFIG_ACK, port_config_payload([0, *others], self.baud))
            return
        try:
            words = parse_port_config(data)
            if len(words) != PORTS_600:
                raise ProtocolError(f"{len(words)} port words, not {PORTS_600}")
            self.pending_baud = port_config_baud(words)
        except ProtocolError:
            self._error(ERROR_INVALID_BAUD)
            return
        self._reply(MID.PORT_CONFIG_ACK)

    def _on_baudrate(self, data: bytes) -> None:
        if not data:
            self._reply(MID.BAUDRATE_ACK, baudrate_payload(self.baud))
            return
        try:
            self.pending_baud = parse_baudrate(data)  # applies after Reset / power cycle
        except ProtocolError:
            self._error(ERROR_INVALID_BAUD)
            return
        self._reply(MID.BAUDRATE_ACK)

    def _on_output_configuration(self, data: bytes) -> None:
        """Set (when ``data``) and echo the configuration; a recording's device sends what it sent (and
        refuses the orientation outputs it did not send)."""
        recorded = self.source.configuration is not None
        if data:
            try:
                effective = effective_configuration(parse_output_configuration(data))
            except ProtocolError:
                effective = []
            if not (effective or recorded) or any(item.name in self.refuses for item in effective):
                self._error(ERROR_INVALID_PARAMETER)
                return
            if not recorded:
                self.output.items = effective
        echo = self.source.configuration or self.output.entries
        self._reply(MID.OUTPUT_CONFIGURATION_ACK, output_configuration_payload(echo))

    def _on_goto_measurement(self, _: bytes) -> None:
        if self.output.legacy:
            try:
                self.output.legacy_mode.check_simulated()
            except ProtocolError:
                self._error(ERROR_INVALID_PARAMETER)
                return
        self._start_measuring(ack=True)

    def _start_measuring(self, ack: bool = False) -> None:
        if ack:
            self._reply(MID.GOTO_MEASUREMENT_ACK)
        self.measuring = True
        now = self.device_time()
        if self.source.plays_from_measurement and not self._rolling:
            # a recording starts rolling with the first measurement after power-up, its first frame
            # one period after the ack (as a device's first sample comes), not glued to it
            self._origin_s = now + 1 / self.source.rate_hz(self.output)
            self._rolling = True
        # Frames follow the device clock: the first one sent is the next one due from now on.
        self._next_frame = self.source.due(now - self._origin_s, self.output, strict=True)

    # ---- streaming ----------------------------------------

    def stall(self, seconds: float, first: int | None = None) -> None:
        """Frames of ``seconds`` of device time from ``first`` (default: the next) are never sent:
        exactly ``seconds`` times the output rate of them, however the threads are scheduled."""
        start = self._next_frame if first is None else first
        self._stalled = (start, start + round(seconds * self.source.rate_hz(self.output)))

    def frame_due_at(self, device_s: float) -> int:
        """The first frame due at or after ``device_s`` of device time."""
        return self.source.due(device_s - self._origin_s, self.output, strict=True)

    def _produce_frames(self) -> None:
        if not self.measuring:
            return
        now = self.device_time() - self._origin_s
        due = self.source.due(now, self.output)
        if due <= self._next_frame:
            return
        catch_up = int(self.source.rate_hz(self.output) * self.speed) + 1  # at most one second per turn
        due = min(due, self._next_frame + catch_up)
        start, self._next_frame = self._next_frame, due
        self._last_burst = time.monotonic()
        frames = self.source.frames(start, due, self.output)
        first, stop = self._stalled
        sent = [f for k, f in enumerate(frames, start) if not first <= k < stop]
        if not sent:
            return
        self.frames_sent += len(sent)
        data, corrupted, dropped = self.faults.inject(b"".join(sent), self._rng)
        self.bytes_corrupted += corrupted
        self.bytes_dropped += dropped
        self._send(data)

    def _send(self, data: bytes) -> None:
        self._outbox += data
