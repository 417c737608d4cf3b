"""A simulated Xsens MTi-G on a real pseudo-terminal: the driver opens it exactly like hardware.

``SimulatedMTi`` puts the parts together and runs them on a background thread, as gpsfake
runs a log source through a fake pty: a ``FrameSource`` (the scripted physics of a
``DecayScenario``, or a recording's raw bytes), the ``Firmware`` (the MT messages and device
states) and a ``PtyLink`` (the pty, its stable and by-id links, the baud rate). It also fires the
faults of a tank (``Faults``): corrupted and dropped bytes, a stall, an unplugged cable and a
re-plug under a new pty name behind the same links, so the driver finds it again by USB serial.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import queue
import select
import threading
from collections.abc import Callable
from pathlib import Path

from ...config.hulls import hull_scenario
from ...errors import InputError
from ...physics.scenario import DecayScenario
from ...physics.truth import RunTruth
from ...xsens.constants import SERIAL_BAUDS
from ..ports import by_id_name
from .faults import Faults
from .firmware import Behaviour, Firmware, ReceivedMessage
from .identity import DeviceIdentity
from .output import OutputItem
from .pty_link import PtyLink
from .sources import FrameSource, RecordedSource, ScenarioSamples, ScriptedSource


class SimulatedMTi:
    """An MTi-G on a pty, run by a background thread (context manager, or ``start``/``stop``).

    It plays ``scenario`` (default: one decay of the default hull), or ``source`` (a
    ``ScriptedSource`` or a ``RecordedSource``). ``port`` is the current /dev/pts/N; ``link`` a
    stable symlink to it that survives a re-plug (open ``link`` when testing reconnection).
    ``speed`` > 1 plays the device clock faster than real time for tests.
    """

    def __init__(
        self,
        scenario: DecayScenario | None = None,
        *,
        source: FrameSource | None = None,
        speed: float = 1.0,
        legacy: bool = False,
        baud: int = 115200,
        faults: Faults | None = None,
        link: str | Path | None = None,
        identity: DeviceIdentity | None = None,
        behaviour: Behaviour | None = None,
        seed: int = 0,
    ) -> None:
        if isinstance(speed, bool) or not isinstance(speed, int | float) or not math.isfinite(speed):
            raise InputError(
                f"speed must be a finite number (the device clock against the wall's), got {speed!r}"
            )
        if speed <= 0:
            raise InputError(f"speed must be positive, got {speed:g}")
        if baud not in SERIAL_BAUDS:
            raise InputError(f"baud {baud} is not an MTi serial rate; use one of {list(SERIAL_BAUDS)}")
        if scenario is not None and source is not None:
            raise InputError("give the simulator a scenario or a source, not both")
        if legacy and isinstance(source, RecordedSource):
            raise InputError("a recording plays MTData2 as recorded: it cannot be a legacy (MTData) device")
        self.source: FrameSource = source or ScriptedSource(scenario or _default_scenario())
        self.speed = speed
        self.faults = faults or Faults()
        self.identity = (
            identity
            or self.source.identity
            or (DeviceIdentity.legacy_mti_g() if legacy else DeviceIdentity.mti_g_710())
        )
        self.behaviour = behaviour or Behaviour()
        name = by_id_name("Xsens", self.identity.product_code, self.identity.serial_number)
        self.line = PtyLink(name, link, seed)
        self.firmware = Firmware(
            self.source, self.line, identity=self.identity, behaviour=self.behaviour, baud=baud, speed=speed,
            legacy=legacy, faults=self.faults, seed=seed,
        )  # fmt: skip
        self._commands: queue.SimpleQueue[Callable[[], None]] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._running = threading.Event()
        self._plugged, self._unplugged = threading.Event(), threading.Event()
        self._replug_timer: threading.Timer | None = None
        self._wake_r, self._wake_w = os.pipe()
        self._fired: set[str] = set()

    # ---- life cycle ----------------------------------------

    def __enter__(self) -> SimulatedMTi:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> SimulatedMTi:
        """Open the pty, power the device up (WakeUp) and start serving in a background thread."""
        if self._thread is not None:
            return self
        if isinstance(self.source, ScriptedSource):
            self.source.prepare()  # compute the scenario now, not in the first sample's turn
        try:
            self.line.create()
            self._plug()
            if self.behaviour.measuring_at_start or self.behaviour.stuck:
                self.firmware.already_measuring()
        except BaseException:
            self.line.remove()
            raise
        self._running.set()
        self._thread = threading.Thread(target=self._serve, name="SimulatedMTi", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and remove the pty, the links and the temporary folder."""
        self._running.clear()
        if self._replug_timer is not None:
            self._replug_timer.cancel()  # a scheduled replug never plugs a device that is gone
        self._wake()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        self._plugged.clear()
        self._unplugged.set()
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._wake_r = self._wake_w = -1
        self.line.remove()

    # ---- what people and tests look at ----------------------------------------

    @property
    def port(self) -> str:
        return self.line.port

    @property
    def link(self) -> str:
        return self.line.link

    @property
    def by_id_dir(self) -> str:
        return self.line.by_id_dir

    @property
    def plugged(self) -> bool:
        return self._plugged.is_set()

    def wait_plugged(self, plugged: bool = True, timeout_s: float | None = None) -> bool:
        """Wait until the device is plugged in (``plugged``) or out, its pty and links already made or
        gone; False when ``timeout_s`` passed first."""
        return (self._plugged if plugged else self._unplugged).wait(timeout_s)

    @property
    def baud(self) -> int:
        return self.firmware.baud

    @property
    def measuring(self) -> bool:
        return self.firmware.measuring

    @property
    def config(self) -> list[OutputItem]:
        return self.firmware.output.items

    @property
    def commands_seen(self) -> list[int]:
        """The message ids the device heard and acted on, in order."""
        return self.firmware.commands_seen

    @property
    def received(self) -> list[ReceivedMessage]:
        """Every message the host wrote (mid, payload, heard), in order; a copy."""
        return list(self.firmware.received)

    @property
    def frames_sent(self) -> int:
        return self.firmware.frames_sent

    @property
    def bytes_corrupted(self) -> int:
        return self.firmware.bytes_corrupted

    @property
    def bytes_dropped(self) -> int:
        return self.firmware.bytes_dropped

    @property
    def bytes_overflowed(self) -> int:
        return self.line.bytes_overflowed

    @property
    def truth(self) -> list[RunTruth]:
        """The scenario's runs (release instants in s from power-up and in SampleTimeFine ticks;
        release indices at the scenario's rate); none for a recording."""
        return self.source.truth

    @property
    def start_ticks(self) -> int:
        return self.source.start_ticks

    def device_time(self) -> float:
        """Seconds on the device clock since power-up."""
        return self.firmware.device_time()

    def play(self, scenario: DecayScenario) -> None:
        """Play ``scenario`` next, on the same clock, the device streaming on (a guided session's next
        decay: one device for the whole session), computed at the configured output rate first, then
        retimed to start a moment of wall time from now on the device's clock and counter. The device
        keeps its own biases: a sensor's still water does not step between decays."""
        source = self.source
        if not isinstance(source, ScriptedSource):
            raise InputError("only a scripted simulated sensor plays another scenario")
        device_biases = source.scenario.sensor_bias_seed
        samples = ScenarioSamples(
            dataclasses.replace(scenario, rate_hz=self.firmware.output.rate_hz, bias_seed=device_biases)
        )
        lead_s = 0.1
        while not source.then_play(
            self.firmware.frame_due_at(self.device_time() + lead_s * self.speed), samples
        ):
            lead_s *= 2  # the device's thread was ahead of its clock: start later

    # ---- faults from Python ----------------------------------------

    def unplug(self) -> None:
        """Pull the cable: the pty closes, its path and the symlink vanish."""
        self._call(self._unplug)

    def replug(self) -> None:
        """Plug back in: a new pty (new /dev/pts number) behind the same symlink; the device boots."""
        self._call(self._plug)

    def stall(self, seconds: float) -> None:
        """The device goes silent for ``seconds`` of device time from its next sample (that data is lost,
        not queued): exactly ``seconds`` times the output rate samples, however the threads are scheduled."""
        self._call(lambda: self.firmware.stall(seconds))

    def set_faults(self, faults: Faults) -> None:
        def switch() -> None:
            self.faults = self.firmware.faults = faults

        self._call(switch)

    def _plug(self) -> None:
        self.line.plug()
        self.firmware.power_up()
        self._unplugged.clear()
        self._plugged.set()

    def _unplug(self) -> None:
        """The pty and its links go first: whoever sees ``plugged`` turn False finds them gone."""
        self.line.unplug()
        self.firmware.measuring = False
        self._plugged.clear()
        self._unplugged.set()

    def _fire_scheduled_faults(self) -> None:
        f, now = self.faults, self.device_time()
        if f.stall_at_s >= 0 and now >= f.stall_at_s and "stall" not in self._fired:
            self._fired.add("stall")
            self.firmware.stall(f.stall_s, first=self.firmware.frame_due_at(f.stall_at_s))
        if f.unplug_at_s >= 0 and now >= f.unplug_at_s and "unplug" not in self._fired:
            self._fired.add("unplug")
            self._unplug()
            if f.replug_after_s >= 0:
                self._replug_timer = threading.Timer(f.replug_after_s / self.speed, self.replug)
                self._replug_timer.daemon = True
                self._replug_timer.start()

    # ---- the device loop ----------------------------------------

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

    def _drain_wake(self) -> None:
        with contextlib.suppress(OSError):
            os.read(self._wake_r, 4096)

    def _serve(self) -> None:
        while self._running.is_set():
            while not self._commands.empty():
                self._commands.get()()
            master = self.line.master
            if master < 0:
                select.select([self._wake_r], [], [], 0.05)
                self._drain_wake()
                continue
            self._fire_scheduled_faults()
            self.firmware.tick()
            master = self.line.master
            if master < 0:
                continue  # unplugged by a scheduled fault
            wanted_write = [master] if self.firmware.has_output else []
            timeout = self.firmware.next_due_s()
            try:
                readable, _, _ = select.select([master, self._wake_r], wanted_write, [], timeout)
            except (OSError, ValueError):
                continue
            if self._wake_r in readable:
                self._drain_wake()
            if master in readable and self.line.master == master:
                self.firmware.receive(self.line.read())
            if self.line.master >= 0:
                self.firmware.send_due()


def _default_scenario() -> DecayScenario:
    """One decay of the default hull (its ``[simulation]`` coefficients)."""
    return hull_scenario(runs=1)
