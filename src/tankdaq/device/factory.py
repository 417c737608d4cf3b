"""``open_device(port, ...)``: the one way a recorder gets an opened, configured MTi.

The port ``sim`` is the built-in simulated MTi-G: it is started on a pseudo-terminal, in a process of
its own as a sensor is hardware (``device.simulator.process``), and opened by path like hardware;
``sim:FILE.mcap`` is the same simulator playing the device of a recording (the caller reads the file:
``device.simulator.playback.recorded_device``); any other port is the real driver on that path (or
pyserial URL). Whoever records (the daemon, a guided session) never tests for ``sim`` to get a device.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..config.hulls import format_draft
from ..errors import InputError
from ..xsens.control import check_bandwidth, decay_output_configuration
from .driver import MTiDriver
from .latency import ftdi_latency_ms, latency_note

if TYPE_CHECKING:
    from ..physics.scenario import DecayScenario
    from .simulator import RecordedSource
    from .simulator.process import SimulatorProcess

#: The port name that starts the built-in simulated MTi-G (``sim:FILE.mcap``: playing a recording).
SIM_PORT = "sim"

#: Standard baud rates tried, smallest first, when the simulated sensor needs a faster line.
SIM_BAUDS = (115200, 230400, 460800, 921600)

#: How long the driver waits for each reply of the simulated sensor, in seconds. Hardware answers in
#: milliseconds and the driver's own timeouts are set for it; the simulator is a process on the same
#: machine, and a machine busy on every core can keep it from answering within a second. It always
#: answers (no stuck or slow behaviour is played on port ``sim``), so waiting longer costs nothing.
SIM_REPLY_TIMEOUT_S = 15.0


@dataclass(frozen=True)
class SimPort:
    """A port that names the simulator: the scripted scenario, or a recording whose device plays again."""

    recording: Path | None = None

    @classmethod
    def parse(cls, port: str) -> SimPort | None:
        """``sim`` -> the scripted scenario; ``sim:FILE.mcap`` -> that file's device; other ports None."""
        name, colon, rest = port.partition(":")
        if name != SIM_PORT:
            return None
        if not colon:
            return cls()
        if not rest:
            raise InputError("--port sim:FILE.mcap needs the recording to play after 'sim:'")
        return cls(Path(rest))


def is_simulated(port: str) -> bool:
    """Whether ``port`` names the built-in simulated sensor (scripted or playing a recording)."""
    return SimPort.parse(port) is not None


@dataclass(frozen=True)
class SimulatedSensor:
    """What the simulated MTi-G plays when the port is ``sim``: the scenario is built only then;
    ``recorded`` (port ``sim:FILE.mcap``): a recording's device instead."""

    scenario: Callable[[], DecayScenario]
    speed: float = 1.0
    seed: int = 0
    legacy: bool = False  # a 2007-era MTi-G (legacy MTData)
    recorded: RecordedSource | None = None


@dataclass(frozen=True)
class DeviceNote:
    """What opening a device tells the caller: ``text`` the line a person reads; ``simulator_link`` the pty
    link of the simulated MTi-G it started (on that line), None on any other note."""

    text: str
    simulator_link: str | None = None


@dataclass
class OpenDevice:
    """An opened, configured device: the driver, and the simulator behind it for port ``sim`` (in a
    process of its own: ``device.simulator.process``)."""

    driver: MTiDriver
    simulator: SimulatorProcess | None = None

    def close(self) -> None:
        """Close the port, then stop the simulator (the link first, as an unplugged cable)."""
        try:
            self.driver.close()
        finally:
            if self.simulator is not None:
                self.simulator.stop()


def sim_baud(rate_hz: float) -> int:
    """The slowest standard line that carries the decay outputs at ``rate_hz``."""
    entries = decay_output_configuration(int(rate_hz))
    return next((b for b in SIM_BAUDS if check_bandwidth(entries, rate_hz, b).ok), SIM_BAUDS[-1])


def open_device(
    port: str,
    rate_hz: float = 100.0,
    baud: int | None = None,
    sim: SimulatedSensor | None = None,
    on_event: Callable[[DeviceNote], None] | None = None,
) -> OpenDevice:
    """Start the simulator for ``sim``, open the driver on the port and configure it for ``rate_hz``.

    ``baud`` None keeps the device's rate when it carries the output. Whatever fails on the way,
    what was started is stopped before the error is passed on.
    """
    say = on_event or (lambda _note: None)
    simulator = None
    if is_simulated(port):
        if sim is None:
            raise InputError("port sim needs a scenario for the simulated sensor to play")
        simulator = _start_simulator(sim, baud or sim_baud(rate_hz), say)
        port = simulator.link
    device = OpenDevice(
        _driver(port, baud, rate_hz, simulator),
        simulator,
    )
    try:
        device.driver.open()
        info = device.driver.configure()
        for note in (
            info.orientation.line(),  # roll and pitch from other than Euler angles: what and why
            latency_note(device.driver.path, ftdi_latency_ms(device.driver.path), rate_hz),
        ):
            if note:
                say(DeviceNote(note))
    except BaseException:  # Ctrl-C while opening too: nothing started is left running
        device.close()
        raise
    return device


def _driver(port: str, baud: int | None, rate_hz: float, simulator: SimulatorProcess | None) -> MTiDriver:
    """The driver for ``port``: hardware's timeouts, or the patient ones of the simulated sensor."""
    if simulator is None:
        return MTiDriver(port, baud=baud, rate_hz=rate_hz)
    patient = SIM_REPLY_TIMEOUT_S
    return MTiDriver(
        port,
        baud=baud,
        rate_hz=rate_hz,
        probe_first=simulator.baud,
        step_timeout_s=patient,
        flash_timeout_s=patient,
        goto_config_s=patient,
    )


def _start_simulator(sim: SimulatedSensor, baud: int, say: Callable[[DeviceNote], None]) -> SimulatorProcess:
    from .simulator.process import SimulatorProcess

    if sim.recorded is not None:
        simulator = SimulatorProcess(source=sim.recorded, speed=sim.speed, baud=baud).start()
        label = f"playing the device of {sim.recorded.name}: {len(sim.recorded)} frames"
    else:
        scenario = sim.scenario()
        simulator = SimulatorProcess(
            scenario, speed=sim.speed, baud=baud, seed=sim.seed, legacy=sim.legacy
        ).start()
        label = f"{scenario.hull} {format_draft(scenario.draft)} {scenario.axis}, seed {scenario.seed}"
    try:
        say(DeviceNote(f"simulated MTi-G on {simulator.link} ({label})", simulator.link))
    except BaseException:  # a Ctrl-C as it is said: nothing started is left running
        simulator.stop()
        raise
    return simulator
