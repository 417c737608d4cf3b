"""A simulated Xsens MTi-G on a real pseudo-terminal: the driver opens it exactly like hardware.

The simulator owns the master side of a pty (raw mode, slave kept open so reads never hit
EIO) and plays a ``DecayScenario`` on the device clock: sample ``k`` is due ``k / rate``
seconds (divided by ``speed``) after power-up, whether or not anyone listens, as on a real
MTi. It answers the configuration messages a driver uses, honours SetOutputConfiguration
(outputs, rates, precision; the ack echoes what it will really send), paces its bytes to the
baud rate, and speaks the 2007-era MTData (0x32) protocol when ``legacy=True``.

Fault injection covers what goes wrong in a tank: corrupted and dropped bytes, a stall, an
unplugged cable (the pty closes and its path vanishes) and a re-plug (a new pty name behind the
same stable symlink). Like udev's ``/dev/serial/by-id``, the device keeps a by-id folder with a
``usb-Xsens_<product>_<serial>-if00-port0`` link to its pty, named in ``TANKDAQ_SERIAL_BY_ID``
while it runs, so the driver finds it again by USB serial number after a re-plug.

Device states a lab meets (``Behaviour``): stuck in measurement, ignoring GoToConfig until a
Reset; slow flash writes; a boot of some seconds after Reset before the WakeUp; a baud rate
that changes only after Reset (the host must reopen at the new rate: the simulator reads the
slave's termios speed); a 600-series product that sets its baud rate with PortConfig.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import errno
import math
import os
import pty
import queue
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, ProtocolError
from ..physics.scenario import (
    TICK_MODULUS,
    TICKS_PER_S,
    DecayScenario,
    RunTruth,
    SensorModel,
    still_trace,
)
from ..xsens.constants import BAUD_CODES, FLASH_WRITES, MID, SERIAL_BAUDS, baud_code
from ..xsens.control import (
    MAX_FREQUENCY,
    PER_MESSAGE_OUTPUTS,
    output_configuration_payload,
    parse_port_config,
    port_config_baud,
)
from ..xsens.frame import Frame, build_frame
from ..xsens.framer import StreamFramer
from ..xsens.legacy import encode_mtdata
from ..xsens.mtdata2 import FRAME_MASK, SPEC_BY_BASE, TYPE_MASK, encode_mtdata2, make_xdi
from .attitude import quaternion
from .legacy_output import LegacyOutput, sample_values
from .ports import BY_ID_ENV, by_id_name

#: Rates an MTi-G-710 can output: divisors of 400 Hz (the echo rounds a request down to one).
DEVICE_RATES_HZ = (1, 2, 4, 5, 8, 10, 16, 20, 25, 40, 50, 80, 100, 200, 400)
MAX_RATE_HZ = 400
#: Outputs the simulator can produce (a request for others is dropped from the echoed configuration).
SUPPORTED_OUTPUTS = frozenset(
    {"PacketCounter", "SampleTimeFine", "SampleTimeCoarse", "EulerAngles", "Quaternion", "RateOfTurn",
     "Acceleration", "StatusWord", "StatusByte"}
)  # fmt: skip
#: Answer to the host's WakeUpAck must come within this time after WakeUp, else the device measures.
WAKEUP_WINDOW_S = 0.5
ERROR_INVALID_MESSAGE = 0x04
ERROR_INVALID_PARAMETER = 0x21
ERROR_INVALID_BAUD = 0x20
#: Temporary folders of simulators: ``tankdaq-sim-<random>`` holding ``owner.pid``.
TEMP_PREFIX = "tankdaq-sim-"
OWNER_FILE = "owner.pid"
#: Ports of a 600-series device (PortConfig words): the host port first.
PORTS_600 = 3


@dataclass(frozen=True)
class DeviceIdentity:
    """What the device says about itself."""

    device_id: int
    product_code: str
    firmware: bytes  # raw ReqFWRev payload (11 bytes MkIV+, 3 bytes legacy)

    @classmethod
    def mti_g_710(cls) -> DeviceIdentity:
        return cls(0x077B1A2C, "MTi-G-710-2A8G4", struct.pack(">3BII", 1, 8, 2, 35, 0))

    @classmethod
    def legacy_mti_g(cls) -> DeviceIdentity:
        """The public ethz issue #66 device: a 2007-era MTi-G (Mark III)."""
        return cls(0x01500618, "MTi-G-28A53G35", bytes((2, 4, 6)))

    @classmethod
    def mti_630(cls) -> DeviceIdentity:
        """A 600-series unit: 8-byte device id, baud rate through PortConfig."""
        return cls(0x0880_0000_0000_1A2C, "MTi-630-2A8G4", struct.pack(">3BII", 1, 12, 0, 100, 0))

    @property
    def serial_number(self) -> str:
        """The USB serial number (Xsens put the device id there)."""
        return f"{self.device_id:08X}"

    @property
    def family_600(self) -> bool:
        return self.product_code.startswith("MTi-6")


@dataclass(frozen=True)
class Behaviour:
    """How the device behaves beyond the protocol's letter (all off: an obliging MTi)."""

    stuck: bool = False  # measuring, it ignores GoToConfig until a Reset (MTi-G-700 field report)
    flash_write_s: float = 0.0  # wall seconds before a flash-writing message is acknowledged
    boot_s: float = 0.0  # wall seconds of silence after a Reset before the WakeUp
    measuring_at_start: bool = False  # powered up before the host came: already streaming


@dataclass(frozen=True)
class Faults:
    """Faults switched on from the start (rates per byte; times in device seconds, -1 = never)."""

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    stall_at_s: float = -1.0
    stall_s: float = 0.0
    unplug_at_s: float = -1.0
    replug_after_s: float = -1.0

    @classmethod
    def parse(cls, text: str) -> Faults:
        """``corrupt=1e-3,drop=1e-4,stall=2@30,unplug=60,replug=5`` (stall S seconds at T)."""
        values: dict[str, float] = {}
        for part in filter(None, (p.strip() for p in text.split(","))):
            key, _, value = part.partition("=")
            try:
                if key == "stall":
                    seconds, _, at = value.partition("@")
                    values["stall_s"], values["stall_at_s"] = float(seconds), float(at or 0.0)
                elif key in ("corrupt", "drop"):
                    values[f"{key}_rate"] = float(value)
                elif key == "unplug":
                    values["unplug_at_s"] = float(value)
                elif key == "replug":
                    values["replug_after_s"] = float(value)
                else:
                    raise ValueError(key)
            except ValueError:
                example = "corrupt=0.001,drop=1e-4,stall=2@30,unplug=60,replug=5"
                raise InputError(f"fault {part!r} not understood; write e.g. {example}") from None
        faults = cls(**values)
        if not (0 <= faults.corrupt_rate < 1 and 0 <= faults.drop_rate < 1):
            raise InputError("corrupt and drop rates are fractions of bytes between 0 and 1")
        return faults


@dataclass
class OutputItem:
    """One configured output: identifier and the frequency the device will really use (Hz)."""

    xdi: int
    hz: int  # MAX_FREQUENCY for outputs that ride along with every message

    @property
    def name(self) -> str:
        return SPEC_BY_BASE[self.xdi & TYPE_MASK].name


def effective_configuration(requested: list[tuple[int, int]]) -> list[OutputItem]:
    """What the device makes of a requested configuration: unsupported outputs dropped, frames
    forced to ENU, rates rounded down to a divisor of 400 Hz, per-message outputs at 0xFFFF."""
    items: list[OutputItem] = []
    for xdi, hz in requested:
        spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
        if spec is None or spec.name not in SUPPORTED_OUTPUTS:
            continue
        if spec.name in PER_MESSAGE_OUTPUTS:
            items.append(OutputItem(xdi, MAX_FREQUENCY))
            continue
        rate = MAX_RATE_HZ if hz in (0, MAX_FREQUENCY) else max(r for r in DEVICE_RATES_HZ if r <= max(hz, 1))
        items.append(OutputItem(xdi & ~FRAME_MASK, rate))
    return items


def default_configuration(rate_hz: int = 100) -> list[OutputItem]:
    """MTi-G-710 factory-like default: counter, time, quaternion, status at 100 Hz."""
    names = ("PacketCounter", "SampleTimeFine", "Quaternion", "StatusWord")
    return effective_configuration([(make_xdi(n), rate_hz) for n in names])


class SampleSource:
    """Samples of the scenario by index on the device clock, then still water for ever."""

    tail_block = 4096

    def __init__(self, scenario: DecayScenario) -> None:
        self.scenario = scenario
        self.samples, self.trace = scenario.samples()
        self._sensor: SensorModel = scenario.sensor()
        self._tail_start = -1
        self._tail = self.samples[:0]

    @property
    def rate_hz(self) -> float:
        return self.scenario.rate_hz

    @property
    def truth(self) -> list[RunTruth]:
        return self.trace.runs

    def block(self, start: int, stop: int) -> np.ndarray:
        """Samples ``start`` .. ``stop - 1``."""
        n = self.samples.size
        if stop <= n:
            return self.samples[start:stop]
        head = self.samples[start:n] if start < n else self.samples[:0]
        parts = [head]
        k = max(start, n)
        while k < stop:
            block_start = n + (k - n) // self.tail_block * self.tail_block
            if block_start != self._tail_start:
                trace = still_trace(self.rate_hz, self.scenario.axis, self.trace.start_ticks, block_start,
                                    self.tail_block)  # fmt: skip
                self._tail = self._sensor.measure(trace, block=1 + block_start // self.tail_block)
                self._tail_start = block_start
            upto = min(stop, block_start + self.tail_block)
            parts.append(self._tail[k - block_start : upto - block_start])
            k = upto
        return np.concatenate(parts)


class SimulatedMTi:
    """An MTi-G on a pty, run by a background thread (context manager, or ``start``/``stop``).

    ``port`` is the current /dev/pts/N; ``link`` a stable symlink to it that survives a
    re-plug (open ``link`` when testing reconnection). ``speed`` > 1 plays the device clock
    faster than real time for tests.
    """

    def __init__(
        self,
        scenario: DecayScenario | None = None,
        *,
        speed: float = 1.0,
        legacy: bool = False,
        baud: int = 115200,
        faults: Faults | None = None,
        link: str | Path | None = None,
        identity: DeviceIdentity | None = None,
        behaviour: Behaviour | None = None,
        seed: int = 0,
    ) -> None:
        if speed <= 0:
            raise InputError(f"speed must be positive, got {speed:g}")
        if baud not in SERIAL_BAUDS:
            raise InputError(f"baud {baud} is not an MTi serial rate; use one of {list(SERIAL_BAUDS)}")
        self.scenario = scenario or DecayScenario(runs=1)
        self.speed = speed
        self.legacy = legacy
        self.baud = baud
        self.faults = faults or Faults()
        self.identity = identity or (DeviceIdentity.legacy_mti_g() if legacy else DeviceIdentity.mti_g_710())
        self.behaviour = behaviour or Behaviour()
        self._own_dir: str | None = None
        self.by_id_dir = ""  # made at start()
        self._by_id_link = ""
        self._last_port = ""
        self.link = str(link) if link else ""  # a temporary one is made at start()
        self._rng = np.random.default_rng([seed, 99])
        self._sources: dict[float, SampleSource] = {}
        self._commands: queue.SimpleQueue[Callable[[], None]] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._running = threading.Event()
        self._plugged = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self.port = ""
        self._master = -1
        self._slave = -1
        # device state (touched only by the thread once started)
        self.config = default_configuration()
        self.legacy_mode = LegacyOutput.default()
        self.measuring = False
        self.pending_baud = baud
        self._epoch = time.monotonic()
        self._next_sample = 0
        self._stalled = (0, 0)  # sample indices [first, stop) that are never sent
        self._fired: set[str] = set()
        self._outbox = bytearray()
        self._budget = 0.0
        self._budget_at = 0.0
        self._framer = StreamFramer()
        self._wakeup_sent_at: float | None = None
        self._booting_until: float | None = None
        self._stuck = self.behaviour.stuck
        # counters people and tests look at
        self.frames_sent = 0
        self.bytes_corrupted = 0
        self.bytes_dropped = 0
        self.bytes_overflowed = 0
        self.commands_seen: list[int] = []

    # ---- life cycle ----------------------------------------

    def __enter__(self) -> SimulatedMTi:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> SimulatedMTi:
        """Open the pty, power the device up (WakeUp) and start serving in a background thread."""
        if self._thread is not None:
            return self
        sweep_stale_folders()
        self._source(self.scenario.rate_hz)  # prepare the scenario now, not in the first sample's turn
        self._own_dir = tempfile.mkdtemp(prefix=TEMP_PREFIX)
        Path(self._own_dir, OWNER_FILE).write_text(f"{os.getpid()}\n")
        atexit.register(self._remove_own_dir)
        self.by_id_dir = os.path.join(self._own_dir, "by-id")
        os.mkdir(self.by_id_dir)
        self._by_id_link = os.path.join(
            self.by_id_dir, by_id_name("Xsens", self.identity.product_code, self.identity.serial_number)
        )
        _register_by_id(self.by_id_dir)
        if not self.link:
            self.link = os.path.join(self._own_dir, "ttyMTi0")
        self._open_pty()
        if self.behaviour.measuring_at_start or self.behaviour.stuck:  # powered long before: no WakeUp
            self._outbox.clear()
            self._wakeup_sent_at = None
            self._start_measuring()
            self._stuck = self.behaviour.stuck
        self._running.set()
        self._thread = threading.Thread(target=self._serve, name="SimulatedMTi", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and remove the pty and the symlink."""
        self._running.clear()
        self._wake()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        self._close_pty()
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1
        self._remove_own_dir()

    def _remove_own_dir(self) -> None:
        """Remove the temporary folder (links, by-id, owner file); also runs at interpreter exit."""
        if self._own_dir:
            _unregister_by_id(self.by_id_dir)
            shutil.rmtree(self._own_dir, ignore_errors=True)
            atexit.unregister(self._remove_own_dir)
            self._own_dir = None

    @property
    def plugged(self) -> bool:
        return self._plugged.is_set()

    def unplug(self) -> None:
        """Pull the cable: the pty closes, its path and the symlink vanish."""
        self._call(self._close_pty)

    def replug(self) -> None:
        """Plug back in: a new pty (new /dev/pts number) behind the same symlink; the device boots."""
        self._call(self._open_pty)

    def stall(self, seconds: float) -> None:
        """The device goes silent for ``seconds`` of device time from its next sample (that data is lost,
        not queued): exactly ``seconds`` times the output rate samples, however the threads are scheduled."""
        self._call(lambda: self._stall_from(self._next_sample, seconds))

    def _stall_from(self, first: int, seconds: float) -> None:
        self._stalled = (first, first + round(seconds * self._rate_hz()))

    def set_faults(self, faults: Faults) -> None:
        self._call(lambda: setattr(self, "faults", faults))

    def device_time(self) -> float:
        """Seconds on the device clock since power-up."""
        return (time.monotonic() - self._epoch) * self.speed

    @property
    def truth(self) -> list[RunTruth]:
        """The scenario's runs (release instants in s from power-up and in SampleTimeFine ticks;
        release indices at the scenario's rate)."""
        return self._source(self.scenario.rate_hz).truth

    @property
    def start_ticks(self) -> int:
        return int(self.scenario.start_ticks or 0)

    def _call(self, action: Callable[[], None]) -> None:
        """Run ``action`` on the device thread (or here when not running) and wait for it."""
        if self._thread is None or threading.current_thread() is self._thread:
            action()
            return
        done = threading.Event()

        def run() -> None:
            try:
                action()
            finally:
                done.set()

        self._commands.put(run)
        self._wake()
        done.wait(timeout=5)

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    # ---- pty ----------------------------------------

    def _open_pty(self) -> None:
        if self._master >= 0:
            return
        master, slave = pty.openpty()
        if os.ttyname(slave) == self._last_port:  # a re-plugged USB device comes back under a new name
            held = (master, slave)
            master, slave = pty.openpty()
            for fd in held:
                os.close(fd)
        tty.setraw(slave)  # a cooked slave would echo and mangle the binary stream
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.port = self._last_port = os.ttyname(slave)
        for link in (self.link, self._by_id_link):
            tmp = f"{link}.new"
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            os.symlink(self.port, tmp)
            os.replace(tmp, link)
        self._power_up()
        self._plugged.set()

    def _close_pty(self) -> None:
        self._plugged.clear()
        for link in (self.link, self._by_id_link):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(link)
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
        self.measuring = False

    def _power_up(self, boot_s: float = 0.0) -> None:
        """Boot: the clock restarts, the stored configuration stays (it lives in flash), a pending baud
        rate takes effect, and after ``boot_s`` of silence the WakeUp goes out."""
        self._epoch = time.monotonic()
        self._next_sample = 0
        self._outbox.clear()
        self._framer = StreamFramer()
        self.baud = self.pending_baud
        self.measuring = False
        self._stuck = False
        self._budget, self._budget_at = 0.0, time.monotonic()
        self._wakeup_sent_at = None
        self._booting_until = time.monotonic() + boot_s
        self._finish_boot()

    def _finish_boot(self) -> None:
        if self._booting_until is not None and time.monotonic() >= self._booting_until:
            self._booting_until = None
            self._send(build_frame(MID.WAKEUP))
            self._wakeup_sent_at = time.monotonic()

    # ---- the device loop ----------------------------------------

    def _serve(self) -> None:
        while self._running.is_set():
            while not self._commands.empty():
                self._commands.get()()
            if self._master < 0:
                select.select([self._wake_r], [], [], 0.05)
                self._drain_wake()
                continue
            self._fire_scheduled_faults()
            self._finish_boot()
            if self._wakeup_sent_at is not None and time.monotonic() - self._wakeup_sent_at > WAKEUP_WINDOW_S:
                self._wakeup_sent_at = None  # no WakeUpAck: the device starts measuring on its own
                self._start_measuring()
            timeout = self._next_due_s()
            wanted_write = [self._master] if self._outbox else []
            try:
                readable, _, _ = select.select([self._master, self._wake_r], wanted_write, [], timeout)
            except (OSError, ValueError):
                continue
            if self._wake_r in readable:
                self._drain_wake()
            if self._master in readable:
                self._read_commands()
            if self._master >= 0:
                self._produce_samples()
                self._flush()

    def _drain_wake(self) -> None:
        with contextlib.suppress(OSError):
            os.read(self._wake_r, 4096)

    def _next_due_s(self) -> float:
        if self._booting_until is not None:
            return min(0.02, max(0.0, self._booting_until - time.monotonic()))
        if not self.measuring:
            return 0.02
        due = self._epoch + self._next_sample / (self._rate_hz() * self.speed)
        return min(0.02, max(0.0, due - time.monotonic()))

    def _fire_scheduled_faults(self) -> None:
        f, now = self.faults, self.device_time()
        if f.stall_at_s >= 0 and now >= f.stall_at_s and "stall" not in self._fired:
            self._fired.add("stall")
            self._stall_from(math.ceil(f.stall_at_s * self._rate_hz()), f.stall_s)
        if f.unplug_at_s >= 0 and now >= f.unplug_at_s and "unplug" not in self._fired:
            self._fired.add("unplug")
            self._close_pty()
            if f.replug_after_s >= 0:
                timer = threading.Timer(f.replug_after_s / self.speed, self.replug)
                timer.daemon = True
                timer.start()

    def _read_commands(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                return
            raise
        if not self._line_matches() or self._booting_until is not None:
            return  # at the wrong baud rate the device sees noise; booting, it hears nothing
        for frame in self._framer.feed(data) + self._framer.flush():  # a host writes whole commands
            if self._booting_until is not None:
                break  # a Reset among them: the rest went to a rebooting device
            self.commands_seen.append(frame.mid)
            self._handle(frame)

    def _line_matches(self) -> bool:
        """True when the driver set the pty to the device's baud rate (pty speeds are only labels)."""
        if self._slave < 0:
            return False
        speed = termios.tcgetattr(self._slave)[5]
        wanted = getattr(termios, f"B{self.baud}", None)
        return wanted is None or speed == wanted

    # ---- messages ----------------------------------------

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
            self._flush()
            self._power_up(self.behaviour.boot_s)
            return
        if self.measuring:
            return  # a measuring device ignores all but GoToConfig and Reset
        handlers: dict[int, Callable[[bytes], None]] = {
            MID.GOTO_MEASUREMENT: self._on_goto_measurement,
            MID.REQ_DID: lambda _: self._reply(MID.DEVICE_ID, self._device_id_bytes()),
            MID.REQ_PRODUCT_CODE: lambda _: self._reply(
                MID.PRODUCT_CODE, self.identity.product_code.encode()
            ),
            MID.REQ_FW_REV: lambda _: self._reply(MID.FW_REV, self.identity.firmware),
            MID.REQ_BAUDRATE: self._on_baudrate,
            MID.RESTORE_FACTORY_DEF: self._on_restore_defaults,
        }
        handlers.update(self._legacy_handlers() if self.legacy else self._mkiv_handlers())
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
        def setter(field: str, fmt: str, ack: int) -> Callable[[bytes], None]:
            def handle(data: bytes) -> None:
                if data:
                    try:
                        (value,) = struct.unpack(fmt, data)
                        self.legacy_mode = dataclasses.replace(self.legacy_mode, **{field: value})
                    except (struct.error, ValueError):
                        self._error(ERROR_INVALID_PARAMETER)
                        return
                    self._reply(ack)
                else:
                    self._reply(ack, struct.pack(fmt, getattr(self.legacy_mode, field)))

            return handle

        return {
            MID.OUTPUT_MODE: setter("mode", ">H", MID.OUTPUT_MODE_ACK),
            MID.OUTPUT_SETTINGS: setter("settings", ">I", MID.OUTPUT_SETTINGS_ACK),
            MID.PERIOD: setter("period", ">H", MID.PERIOD_ACK),
        }

    def _device_id_bytes(self) -> bytes:
        return struct.pack(">Q" if self.identity.family_600 else ">I", self.identity.device_id)

    def _on_restore_defaults(self, _: bytes) -> None:
        """Factory settings (output, legacy mode, 115200 baud) apply from the next power-up."""
        self.config = default_configuration()
        self.legacy_mode = LegacyOutput.default()
        self.pending_baud = 115200
        self._reply(MID.RESTORE_FACTORY_DEF_ACK)

    def _on_port_config(self, data: bytes) -> None:
        """600-series: one U32 per port, the baud code in the low byte; applies after a reset."""
        if not data:
            words = [baud_code(self.baud)] + [baud_code(115200)] * (PORTS_600 - 1)
            self._reply(MID.PORT_CONFIG_ACK, struct.pack(f">{PORTS_600}I", *words))
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
            code = next(c for c, rate in BAUD_CODES.items() if rate == self.baud)
            self._reply(MID.BAUDRATE_ACK, bytes((code,)))
            return
        if data[0] not in BAUD_CODES:
            self._error(ERROR_INVALID_BAUD)
            return
        self.pending_baud = BAUD_CODES[data[0]]  # applies after Reset / power cycle
        self._reply(MID.BAUDRATE_ACK)

    def _on_output_configuration(self, data: bytes) -> None:
        if data:
            if len(data) % 4:
                self._error(ERROR_INVALID_PARAMETER)
                return
            requested = [struct.unpack_from(">HH", data, i) for i in range(0, len(data), 4)]
            effective = effective_configuration(requested)
            if not effective:
                self._error(ERROR_INVALID_PARAMETER)
                return
            self.config = effective
        self._reply(
            MID.OUTPUT_CONFIGURATION_ACK, output_configuration_payload([(o.xdi, o.hz) for o in self.config])
        )

    def _on_goto_measurement(self, _: bytes) -> None:
        if self.legacy:
            try:
                self.legacy_mode.check_simulated()
            except ProtocolError:
                self._error(ERROR_INVALID_PARAMETER)
                return
        self._start_measuring(ack=True)

    def _start_measuring(self, ack: bool = False) -> None:
        if ack:
            self._reply(MID.GOTO_MEASUREMENT_ACK)
        self.measuring = True
        # Samples follow the device clock: the first one sent is the next one due from now on.
        rate = self._rate_hz()
        self._next_sample = math.ceil((time.monotonic() - self._epoch) * self.speed * rate)

    # ---- streaming ----------------------------------------

    def _rate_hz(self) -> float:
        if self.legacy:
            return self.legacy_mode.rate_hz
        rates = [o.hz for o in self.config if o.hz != MAX_FREQUENCY]
        return float(max(rates) if rates else 100)

    def _source(self, rate: float | None = None) -> SampleSource:
        """The scenario played at the configured output rate (the truth in s and ticks is the same)."""
        rate = rate or self._rate_hz()
        if rate not in self._sources:
            self._sources[rate] = SampleSource(dataclasses.replace(self.scenario, rate_hz=rate))
        return self._sources[rate]

    def _produce_samples(self) -> None:
        if not self.measuring:
            return
        now = time.monotonic()
        rate = self._rate_hz()
        due = math.floor((now - self._epoch) * self.speed * rate) + 1
        if due <= self._next_sample:
            return
        due = min(due, self._next_sample + int(rate * self.speed) + 1)  # catch up at most one second per turn
        block = self._source().block(self._next_sample, due)
        indices = np.arange(self._next_sample, due)
        self._next_sample = due
        sent = (indices < self._stalled[0]) | (indices >= self._stalled[1])
        if not sent.all():
            block, indices = block[sent], indices[sent]
            if not block.size:
                return
        encoded = self._encode_legacy(block) if self.legacy else self._encode(block, indices, rate)
        self.frames_sent += block.size
        self._send(self._inject(encoded))

    def _encode(self, block: np.ndarray, indices: np.ndarray, rate: float) -> bytes:
        quats = None
        out = bytearray()
        for row, (sample, k) in enumerate(zip(block, indices, strict=True)):
            items: list[tuple[int, object]] = []
            for item in self.config:
                if item.hz != MAX_FREQUENCY and k % max(1, round(rate / item.hz)):
                    continue
                name = item.name
                if name == "Quaternion" and quats is None:
                    quats = quaternion(block["roll"], block["pitch"], block["yaw"])
                items.append((item.xdi, self._value(name, sample, None if quats is None else quats[row])))
            out += build_frame(MID.MTDATA2, encode_mtdata2(items))
        return bytes(out)

    @staticmethod
    def _value(name: str, sample: np.void, quaternion: np.ndarray | None) -> object:
        ticks = int(sample["ticks"])
        values: dict[str, Callable[[], object]] = {
            "PacketCounter": lambda: int(sample["counter"]),
            "SampleTimeFine": lambda: ticks % TICK_MODULUS,
            "SampleTimeCoarse": lambda: (ticks // TICKS_PER_S) & 0xFFFFFFFF,
            "EulerAngles": lambda: tuple(math.degrees(float(sample[f])) for f in ("roll", "pitch", "yaw")),
            "Quaternion": lambda: tuple(float(q) for q in quaternion),  # type: ignore[union-attr]
            "RateOfTurn": lambda: tuple(float(sample[f]) for f in ("p", "q", "r")),
            "Acceleration": lambda: tuple(float(sample[f]) for f in ("ax", "ay", "az")),
            "StatusWord": lambda: int(sample["status"]),
            "StatusByte": lambda: int(sample["status"]) & 0xFF,
        }
        return values[name]()

    def _encode_legacy(self, block: np.ndarray) -> bytes:
        mode, settings = self.legacy_mode.mode, self.legacy_mode.settings
        return b"".join(
            build_frame(MID.MTDATA, encode_mtdata(sample_values(s), mode, settings)) for s in block
        )

    def _inject(self, data: bytes) -> bytes:
        """Corrupt and drop bytes at the configured rates (on data frames only, as line noise would)."""
        f = self.faults
        if not (f.corrupt_rate or f.drop_rate) or not data:
            return data
        arr = np.frombuffer(data, dtype=np.uint8).copy()
        if f.corrupt_rate:
            hit = np.flatnonzero(self._rng.random(arr.size) < f.corrupt_rate)
            arr[hit] ^= self._rng.integers(1, 256, hit.size, dtype=np.uint8)
            self.bytes_corrupted += hit.size
        if f.drop_rate:
            keep = self._rng.random(arr.size) >= f.drop_rate
            self.bytes_dropped += int(arr.size - keep.sum())
            arr = arr[keep]
        return arr.tobytes()

    def _send(self, data: bytes) -> None:
        self._outbox += data
        limit = 1 << 18  # a device's output buffer: beyond it, data is lost (as on a link that is too slow)
        if len(self._outbox) > limit:
            excess = len(self._outbox) - limit
            del self._outbox[:excess]
            self.bytes_overflowed += excess

    def _flush(self) -> None:
        """Write what the baud rate allows since the last write (the pty itself has no speed)."""
        if not self._outbox or self._master < 0:
            return
        now = time.monotonic()
        bytes_per_s = self.baud / 10 * self.speed
        self._budget = min(self._budget + (now - self._budget_at) * bytes_per_s, max(bytes_per_s * 0.05, 256))
        self._budget_at = now
        n = min(len(self._outbox), int(self._budget))
        if n <= 0:
            return
        chunk = bytes(self._outbox[:n])
        if not self._line_matches():  # read at the wrong baud rate, every byte comes out garbled
            chunk = self._rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        try:
            written = os.write(self._master, chunk)
        except BlockingIOError:
            return
        except OSError:
            return  # nobody reads (or the pty went away): keep the bytes, the buffer limit applies
        del self._outbox[:written]
        self._budget -= written


def _register_by_id(folder: str) -> None:
    """Name ``folder`` in ``TANKDAQ_SERIAL_BY_ID`` so this process's port finder sees the device."""
    dirs = [d for d in os.environ.get(BY_ID_ENV, "").split(os.pathsep) if d]
    os.environ[BY_ID_ENV] = os.pathsep.join([*dirs, folder])


def _unregister_by_id(folder: str) -> None:
    dirs = [d for d in os.environ.get(BY_ID_ENV, "").split(os.pathsep) if d and d != folder]
    if dirs:
        os.environ[BY_ID_ENV] = os.pathsep.join(dirs)
    else:
        os.environ.pop(BY_ID_ENV, None)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_stale_folders(root: str | None = None) -> list[Path]:
    """Remove simulator folders whose owner process is dead (a kill -9 leaves them); returns them.

    Folders without an owner file are left alone (they may be being created right now).
    """
    removed = []
    for folder in Path(root or tempfile.gettempdir()).glob(f"{TEMP_PREFIX}*"):
        try:
            pid = int((folder / OWNER_FILE).read_text())
        except (OSError, ValueError):
            continue
        if not _pid_alive(pid):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed
