"""The record daemon: device -> release detection -> one MCAP per decay, live fit and view.

It runs until ``runs`` decays are recorded or it is stopped: Ctrl-C, SIGTERM and SIGHUP (a
closed terminal or SSH session) all close the decay under way as a complete file (``stopped_by``
names the signal) that says it was stopped (``DecayEnd.STOPPED``: partial). A device that vanishes
mid-decay closes that file with what arrived (``DEVICE_LOST``), and the daemon waits for the device
to come back; an exception closes it as ``ERROR``. ``port="sim"`` starts the built-in
simulated MTi-G in-process on a pseudo-terminal, opened like hardware
(``device.factory.open_device``); ``port="sim:FILE.mcap"`` plays the device of that recording
(its raw bytes, at their pace) through the same pty. The decay pipeline is a ``DecayPipeline``
with three sinks: the online identifier, the recording, the live view (``acquire.sinks``), and the
listeners given (``sinks``). What a person is told (the device, held, released, settled, gone, back,
stopping) is a typed event (``acquire.events``) every sink hears; the command line prints them.

Two threads: ``tankdaq-read`` (``acquire.read_thread``) only reads the device and queues the
blocks; the thread that called ``run`` takes them and runs the pipeline, its sinks, the files and
the callbacks, so an error there reaches the caller as before and the reads never wait for it.
"""

from __future__ import annotations

import dataclasses
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import validation
from ..config.hulls import Hull, hull_scenario, load_hull
from ..device.driver import MTiDriver, StreamCounters
from ..device.factory import OpenDevice, SimPort, SimulatedSensor, open_device
from ..device.simulator.playback import recorded_device
from ..errors import DeviceGone, InputError, RecordingError
from ..live.identifier import OnlineIdentifier
from ..live.preparation import prepare_identifier
from ..physics.scenario import fresh_seed
from ..records import DecayEnd
from ..store.disk import RESERVE_BYTES
from ..viz.live import LiveView
from ..viz.view_process import ViewProcess
from ..viz.viewer import default_viewer_mode, describe_mode
from .events import (
    DecayOutcome,
    DeviceBack,
    DeviceLost,
    DeviceReady,
    Event,
    KeptOutcomes,
    Notice,
    Stopped,
    Stopping,
    ViewerNote,
)
from .memory import tune_allocator
from .pipeline import Block, DecayPipeline, DetectionSettings
from .read_thread import DeviceReader, Read
from .signals import SignalStop
from .sinks import IdentifierSink, RecordingSink, Sink, ViewSink

if TYPE_CHECKING:
    from ..device.simulator import RecordedSource, SimulatedMTi
    from ..physics.scenario import DecayScenario

#: The note a decay's file gets when the recording ends with the decay under way, by how it ended.
STOP_NOTES = {
    DecayEnd.STOPPED: "recording stopped by the operator",
    DecayEnd.ERROR: "recording ended by an error",
}

#: What the driver learnt that each recording keeps (``describe_run``).
DEVICE_METADATA = ("device_id", "product_code", "firmware", "baud", "baud_changed_from")


@dataclass(frozen=True)
class RecordSettings:
    """Everything ``tankdaq record`` is told (degrees at this edge); ``check()`` before anything opens."""

    port: str
    draft: float
    angle_deg: float
    hull: str | None = None  # name or .toml path; required by the simulator, never assumed
    axis: str = "roll"  # roll, pitch, auto
    rate_hz: float = 100.0
    baud: int | None = None  # None: the device's rate if it carries the output, else the slowest that does
    out_dir: Path = Path("recordings")
    runs: int | None = None
    viewer: str | None = "none"  # None: the default (spawn with a display, save without)
    viewer_bind: str = "127.0.0.1"  # where a spawned viewer listens; 0.0.0.0 only when asked
    viewer_port: int = 9876
    disk_reserve_bytes: int = RESERVE_BYTES  # the .rrd stops with less free space than this
    operator: str = ""
    note: str = ""
    model: str = "ittc-quadratic-restoring"
    pretrigger_s: float = 2.0
    angle_tolerance_deg: float = 1.0
    reconnect_timeout_s: float = 120.0
    sim_speed: float = 1.0
    sim_seed: int | None = None  # None: a fresh one (``seeded``); the same seed plays the same test
    sim_legacy: bool = False  # the built-in sensor plays a 2007-era MTi-G (legacy MTData)
    sim_overrides: dict[str, object] = field(default_factory=dict)  # DecayScenario settings of a session
    extra: dict[str, object] = field(default_factory=dict)

    def check(self) -> Hull | None:
        """Apply every rule the settings must pass before a simulator starts or a port opens (one
        ``InputError`` line each); returns the hull they name."""
        hull = load_hull(self.hull) if self.hull else None
        if self.axis not in ("roll", "pitch", "auto"):
            raise InputError(f"axis {self.axis!r} not understood; use roll, pitch or auto")
        validation.release_angle_deg(self.angle_deg, option="angle")
        validation.output_rate_hz(self.rate_hz, option="rate")
        validation.baud_rate(self.baud, option="baud")
        validation.baud_carries_rate(self.baud, self.rate_hz, option="--baud")
        validation.live_model(self.model, option="model")
        sim_port = SimPort.parse(self.port)
        if sim_port and sim_port.recording is None:  # refuse a hull the simulator cannot play
            if hull is None:
                raise InputError("the simulated sensor needs a hull to play: give --hull")
            hull.simulated_coefficients(self.simulated_axis, self.draft, self.rate_hz)
        validation.output_dir(self.out_dir, option="output folder")
        return hull

    def recorded_device(self) -> RecordedSource | None:
        """The recording port ``sim:FILE.mcap`` plays, read and checked (its rate is the one asked)."""
        sim_port = SimPort.parse(self.port)
        if sim_port is None or sim_port.recording is None:
            return None
        recorded = recorded_device(sim_port.recording)
        if abs(recorded.nominal_rate_hz - self.rate_hz) > 0.01 * self.rate_hz:
            hz = recorded.nominal_rate_hz
            raise InputError(f"{sim_port.recording} was recorded at {hz:g} Hz: give --rate {hz:g}")
        return recorded

    def seeded(self) -> RecordSettings:
        """These settings with the scripted simulated sensor's seed drawn when none was given: each
        ``record --port sim`` plays decays of its own, and its files say the seed (``sim_seed``)."""
        sim_port = SimPort.parse(self.port)
        if self.sim_seed is not None or sim_port is None or sim_port.recording is not None:
            return self
        return dataclasses.replace(self, sim_seed=fresh_seed())

    @property
    def simulated_axis(self) -> str:
        """The axis the simulated sensor decays on (roll for an auto session)."""
        return "roll" if self.axis == "auto" else self.axis


@dataclass
class DaemonStatus:
    """What the status line shows between runs."""

    state: str = "starting"
    held_deg: float = float("nan")
    runs_done: int = 0
    samples: int = 0
    gaps: int = 0
    bad_frames: int = 0
    device: str = ""

    def line(self, runs_wanted: int | None) -> str:
        state = f"held at {self.held_deg:+.2f} deg" if self.state == "held" else self.state
        wanted = f"/{runs_wanted}" if runs_wanted else ""
        return (
            f"state: {state} | runs {self.runs_done}{wanted} | samples {self.samples} | "
            f"gaps {self.gaps} | bad frames {self.bad_frames}"
        )


class RecordDaemon:
    """``run()`` records decays from the device until done; see the module docstring."""

    def __init__(
        self,
        settings: RecordSettings,
        on_status: Callable[[DaemonStatus], None] | None = None,
        sinks: Sequence[Sink] = (),  # more listeners: the printer of the events, a session's level check
        identifier: Callable[..., OnlineIdentifier] = OnlineIdentifier,  # the live fit (IdentifierSink's)
    ) -> None:
        self.settings = settings.seeded()
        self.on_status = on_status or (lambda _status: None)
        self.status = DaemonStatus()
        self.hull: Hull | None = settings.check()  # before a simulator starts or the port opens
        self.replayed = settings.recorded_device()  # port sim:FILE.mcap: read and checked now, too
        self.extra_sinks = list(sinks)
        self.make_identifier = identifier
        self.device: OpenDevice | None = None
        self.outcomes = KeptOutcomes()  # the newest, filled by the pipeline; a day's would grow
        self._fed_counters = StreamCounters()  # the link as of the last block the pipeline was fed
        self._stop = threading.Event()
        self._signals = SignalStop(self._stop)
        self._recording: RecordingSink | None = None
        self._pipeline: DecayPipeline | None = None

    def emit(self, event: Event) -> None:
        """An event for every listener: through the pipeline once it runs (every sink), before that to
        the listeners given (the device and the viewer are announced before the pipeline exists)."""
        if self._pipeline is not None:
            self._pipeline.emit(event)
            return
        for sink in self.extra_sinks:
            sink.on_event(event)

    def _notice(self, source: str) -> Callable[[str], None]:
        """A part's one-line callback (the device factory, the identifier's kernels) as typed notices."""
        return lambda text: self.emit(Notice(source, text))

    @property
    def stopped_by(self) -> str | None:
        """The signal that stopped ``run`` (SIGINT, SIGTERM, SIGHUP), None when it ran to its end."""
        return self._signals.stopped_by

    @property
    def recordings(self) -> list[Path]:
        """The decay files this daemon wrote that exist: what a summary counts."""
        paths = self._recording.paths if self._recording is not None else []
        return [Path(path) for path in paths if os.path.exists(path)]

    # ---- the device ----------------------------------------

    @property
    def simulator(self) -> SimulatedMTi | None:
        """The simulated sensor behind port ``sim`` once started (its ``truth``, ``unplug()``)."""
        return self.device.simulator if self.device else None

    def simulation_scenario(self) -> DecayScenario:
        """What the built-in simulated sensor plays (deterministic: its runs are the truth)."""
        s = self.settings
        assert self.hull is not None and s.sim_seed is not None  # check() and seeded() on port sim
        scenario = hull_scenario(
            self.hull, s.draft, s.simulated_axis, angle_deg=s.angle_deg, rate_hz=s.rate_hz,
            runs=(s.runs or 20) + 1, seed=s.sim_seed,
        )  # fmt: skip
        return dataclasses.replace(scenario, **s.sim_overrides)  # type: ignore[arg-type]

    def _open_device(self) -> MTiDriver:
        s = self.settings
        sim = SimulatedSensor(
            self.simulation_scenario,
            speed=s.sim_speed,
            seed=s.sim_seed or 0,  # played on port sim only, where seeded() drew it
            legacy=s.sim_legacy,
            recorded=self.replayed,
        )
        say = self._notice("device")
        self.device = open_device(
            s.port, rate_hz=s.rate_hz, baud=s.baud, sim=sim, on_event=lambda note: say(note.text)
        )
        return self.device.driver

    def _file_header(self, driver: MTiDriver) -> tuple[dict[str, object], dict[str, dict[str, object]]]:
        """The metadata and the configuration every recording of these settings carries."""
        from ..store.writer import describe_run

        s = self.settings
        info = driver.info
        device = asdict(info) if info else {}
        metadata = describe_run(
            s.axis,
            s.angle_deg,
            hull=self.hull,
            draft=s.draft,
            sample_rate_hz=s.rate_hz,
            device={k: device.get(k) for k in DEVICE_METADATA},
            operator=s.operator,
            note=s.note,
        )
        metadata["port"] = info.port if info else s.port
        metadata["legacy_protocol"] = bool(info.legacy) if info else False
        if s.sim_seed is not None:  # the scripted simulator's: --seed N plays this test again
            metadata["sim_seed"] = s.sim_seed
        if info is not None:
            metadata.update(info.orientation.metadata())  # orientation_source (and what was refused)
        config = {"record": {k: str(v) if isinstance(v, Path) else v for k, v in asdict(s).items()}}
        config["device"] = {k: v for k, v in device.items() if k != "configuration"}
        config["device"]["configuration"] = [[int(x), int(hz)] for x, hz in device.get("configuration", ())]
        return metadata, config

    def _make_pipeline(self, driver: MTiDriver) -> DecayPipeline:
        s = self.settings
        metadata, config = self._file_header(driver)
        mode = s.viewer or default_viewer_mode()
        self.emit(ViewerNote(describe_mode(mode, default=s.viewer is None)))
        # a view that shows anything runs in a process of its own, replaced every so many decays:
        # what rerun keeps of each recording is given back, and its failures stay there (viz.view_process)
        view = (LiveView if mode == "none" else ViewProcess)(
            mode,
            axis="roll" if s.axis == "auto" else s.axis,
            bind=s.viewer_bind,
            spawn_port=s.viewer_port,
            on_note=lambda line: self.emit(ViewerNote(line)),
            rrd_reserve_bytes=s.disk_reserve_bytes,
        )
        detection = DetectionSettings(
            axis=s.axis,
            angle_deg=s.angle_deg,
            angle_tolerance_deg=s.angle_tolerance_deg,
            pretrigger_s=s.pretrigger_s,
            model=s.model,
        )
        recording = RecordingSink(
            s.out_dir,
            metadata,
            config,
            draft=s.draft,
            nominal_angle_deg=s.angle_deg,
            closing_metadata=lambda: {**driver.closing_metadata(), **self._fed_counters.metadata()},
        )
        self._recording = recording
        identifier = partial(  # the hull's GM and gyradius for the fits' plausibility checks
            self.make_identifier,
            particulars=self.hull.particulars(s.simulated_axis) if self.hull else None,
            hull=self.hull.name if self.hull else "the hull",
        )
        sinks = [IdentifierSink(identifier), recording, ViewSink(view), *self.extra_sinks]
        return DecayPipeline(detection, sinks, self.outcomes)

    # ---- the loop ----------------------------------------

    def run(self) -> list[DecayOutcome]:
        """Record until ``runs`` decays are done or stopped; returns the outcomes of the newest
        ``KEPT_OUTCOMES`` decays (every decay's was a ``Settled`` event; ``outcomes.count``: how many)."""
        with self._signals.installed():
            return self._run()

    def _start(self) -> tuple[MTiDriver, DecayPipeline]:
        """Prepare the kernels (no refit compiles mid-decay), open the device, build the pipeline."""
        s = self.settings
        tune_allocator()  # before the view's, rerun's and the fits' threads (acquire.memory)
        prepare_identifier(s.model, self._notice("identifier"))
        driver = self._open_device()
        self.status.device = driver.info.describe() if driver.info else s.port
        self.emit(DeviceReady(self.status.device))
        pipeline = self._pipeline = self._make_pipeline(driver)
        self.status.state = "waiting"
        return driver, pipeline

    def _run(self) -> list[DecayOutcome]:
        pipeline: DecayPipeline | None = None
        signals = self._signals
        ended = DecayEnd.ERROR  # how a decay under way ends: an exception, unless the loop ends as asked
        try:
            driver, pipeline = self._start()
            while not self._done():
                signals.in_loop = True  # a signal now ends the loop once the blocks read are fed
                try:
                    gone = self._stream(pipeline, DeviceReader(driver).start())
                finally:
                    signals.in_loop = False
                if gone is not None:
                    self._device_gone(driver, pipeline, str(gone))
            ended = DecayEnd.STOPPED  # stopped (a signal, ``stop()``), or the runs done with none under way
        except KeyboardInterrupt:
            signals.stopped_by = signals.stopped_by or "SIGINT"
            ended = DecayEnd.STOPPED
        except RecordingError:
            stopped = "recording stopped: a file could not be written (files already closed are intact)"
            self.emit(Notice("recording", stopped))
            raise
        finally:
            self._finish(pipeline, ended)
        self.emit(Stopped(signals.stopped_by, self.outcomes.count))
        return list(self.outcomes)

    def _finish(self, pipeline: DecayPipeline | None, ended: DecayEnd) -> None:
        """Stopping: the decay under way closed complete (``ended``), then the sinks and the device; a
        second Ctrl-C meanwhile never cuts the file being closed."""
        signals = self._signals
        signals.closing = True
        if signals.stopped_by:
            self.emit(Stopping(signals.stopped_by))
        try:
            self._shut_down(pipeline, ended)
        finally:
            signals.closing = False
            self._pipeline = None  # closed: what is said now goes to the listeners given

    def stop(self) -> None:
        """Ask ``run`` to return once the blocks already read are fed (from a callback or another thread)."""
        self._stop.set()

    def _shut_down(self, pipeline: DecayPipeline | None, ended: DecayEnd) -> None:
        """Close the decay under way as ``ended`` (its file stays readable), the sinks (the viewer), the
        device."""
        try:
            if pipeline is not None:
                pipeline.abort(ended, STOP_NOTES[ended])
        except RecordingError as exc:  # the disk is full: the file is left for tankdaq recover
            self.emit(Notice("recording", str(exc)))
        finally:
            try:
                if pipeline is not None:
                    pipeline.close()
            finally:
                if self.device is not None:
                    self.device.close()

    def _done(self) -> bool:
        return self._stop.is_set() or self._runs_done()

    def _stream(
        self, pipeline: DecayPipeline, reader: DeviceReader, until: Callable[[], bool] | None = None
    ) -> DeviceGone | None:
        """Feed ``reader``'s blocks to the pipeline until done (returns None) or the device is gone
        (returns why). Stopped, every block read is fed; once ``runs`` are done the rest is not (the
        reads after the last decay wanted could only start one more). ``until``: a guided session's
        step is over; the reader is left reading (the blocks wait in its queue for the next step)."""
        ended = False
        try:
            for item in reader.items(until=self._done):
                if not isinstance(item, Read):  # the reader ended: stopped, the device gone, or a failure
                    ended = True
                    if isinstance(item.error, DeviceGone) or item.error is None:
                        return item.error
                    raise item.error
                if not self._runs_done():
                    self._feed(pipeline, item)
                if until is not None and until():
                    return None
            return None
        finally:
            if ended or until is None:
                reader.close()

    def _runs_done(self) -> bool:
        runs = self.settings.runs
        return runs is not None and self.outcomes.count >= runs

    def _feed(self, pipeline: DecayPipeline, read: Read) -> None:
        block = read.block
        pipeline.feed(Block(block.samples, block.raw, block.host_t, block.carried))
        self._fed_counters = c = read.counters
        st = self.status
        st.samples, st.gaps, st.bad_frames = c.samples, c.gaps, c.bad_frames
        st.state, st.held_deg, st.runs_done = pipeline.state, pipeline.held_deg, self.outcomes.count
        self.on_status(st)

    def _device_gone(self, driver: MTiDriver, pipeline: DecayPipeline, message: str) -> None:
        pipeline.abort(DecayEnd.DEVICE_LOST, message)
        self.status.state = "device gone: waiting for it to come back"
        self.on_status(self.status)
        self.emit(DeviceLost(message, self.settings.reconnect_timeout_s))
        started = time.monotonic()
        driver.reconnect(timeout_s=self.settings.reconnect_timeout_s)
        self.emit(DeviceBack(time.monotonic() - started))
        self.status.state = "waiting"
