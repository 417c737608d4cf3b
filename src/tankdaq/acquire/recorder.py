"""The recorder: the device, the decay pipeline and its sinks, fed block by block (``open``, ``feed``,
``retarget``, ``close``); ``record`` (``acquire.daemon.RecordDaemon``) and the guided session
(``acquire.streaming.SessionStream``) each compose one.

``port="sim"`` starts the built-in simulated MTi-G in-process on a pseudo-terminal, opened like hardware
(``device.factory.open_device``); ``port="sim:FILE.mcap"`` plays the device of that recording (its raw
bytes, at their pace) through the same pty. The pipeline fits each decay (``acquire.decay.LiveFit``) and
has the recording, the live view (``acquire.sinks``) and the listeners given as its sinks. What a person is
told (the device, held, released, settled, gone, back) is a typed event (``acquire.events``) every sink
hears. A device that vanishes mid-decay closes that file with what arrived (``DEVICE_LOST``), and the
recorder waits for it to come back.

Two threads: ``tankdaq-read`` (``acquire.read_thread``) only reads the device and queues the blocks; the
thread that calls ``feed`` takes them and runs the pipeline, its sinks, the files and the callbacks, so an
error there reaches the caller and the reads never wait for it. Stopping is the ``SignalStop`` it is given
(``acquire.signals``): its phase says what a signal does, its ``stop`` ends ``feed``.
"""

from __future__ import annotations

import dataclasses
import os
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
from ..viz.view_process import View, ViewProcess
from ..viz.viewer import DEFAULT_BIND, default_viewer_mode, describe_mode
from ..viz.web_viewer import DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT, WebServer, is_web
from .decay import LiveFit
from .events import DeviceBack, DeviceLost, DeviceReady, Event, KeptOutcomes, Notice, ViewerNote
from .live_panel import LivePanel, open_web_viewer
from .memory import tune_allocator
from .pipeline import DecayPipeline, DetectionSettings
from .read_thread import DeviceReader, Read
from .signals import Phase, SignalStop
from .sinks import RecordingSink, Sink, ViewSink

if TYPE_CHECKING:
    from ..device.simulator import RecordedSource
    from ..device.simulator.process import SimulatorProcess
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
    viewer_bind: str | None = None  # where a viewer listens (None: spawn 127.0.0.1, web the LAN address)
    viewer_port: int = DEFAULT_GRPC_PORT  # a spawned viewer's, or the web viewer's data server
    viewer_web_port: int = DEFAULT_WEB_PORT  # the web viewer's page
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


class Recorder:
    """The device and the pipeline fed block by block: ``open()``, then ``feed(until)`` as often as the
    orchestrator asks (``retarget`` between decays), then ``close(ended)``; see the module docstring.

    ``stop`` is the orchestrator's ``SignalStop`` (``record``'s and a session's own): the recorder sets
    its phase while it feeds and closes, and ``feed`` ends once a stop is asked.
    """

    def __init__(
        self,
        settings: RecordSettings,
        on_status: Callable[[DaemonStatus], None] | None = None,
        sinks: Sequence[Sink] = (),  # more listeners: the printer of the events, a session's level check
        identifier: Callable[..., OnlineIdentifier] = OnlineIdentifier,  # the live fit's (``LiveFit``)
        stop: SignalStop | None = None,
    ) -> None:
        self.settings = settings.seeded()
        self.on_status = on_status or (lambda _status: None)
        self.status = DaemonStatus()
        self.hull: Hull | None = settings.check()  # before a simulator starts or the port opens
        self.replayed = settings.recorded_device()  # port sim:FILE.mcap: read and checked now, too
        self.extra_sinks = list(sinks)
        self.make_identifier = identifier
        self.signals = stop or SignalStop()
        self.device: OpenDevice | None = None
        self.outcomes = KeptOutcomes()  # the newest, filled by the pipeline; a day's would grow
        self._fed_counters = StreamCounters()  # the link as of the last block the pipeline was fed
        self._recording: RecordingSink | None = None
        self._pipeline: DecayPipeline | None = None
        self._driver: MTiDriver | None = None
        self._reader: DeviceReader | None = None
        self._web: WebServer | None = None  # --viewer web: its server, for the whole run

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
    def recordings(self) -> list[Path]:
        """The decay files this recorder wrote that exist: what a summary counts."""
        paths = self._recording.paths if self._recording is not None else []
        return [Path(path) for path in paths if os.path.exists(path)]

    @property
    def decay_under_way(self) -> bool:
        """Whether a decay is being recorded (released, not yet settled)."""
        return self._pipeline is not None and self._pipeline.decay is not None

    @property
    def queued_blocks(self) -> int:
        """Blocks read and not yet fed (the reading thread's queue): what a pause in the feeding piles up."""
        return self._reader.queued if self._reader is not None else 0

    def runs_done(self) -> bool:
        """Whether the ``runs`` decays asked for are recorded (never, with no number asked)."""
        runs = self.settings.runs
        return runs is not None and self.outcomes.count >= runs

    # ---- the device ----------------------------------------

    @property
    def simulator(self) -> SimulatorProcess | None:
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

    def _make_views(self) -> list[View]:
        """The live views: none, or one in a process of its own, replaced every so many decays (what rerun
        keeps of each recording is given back, its failures stay there: viz.view_process); with web+save
        two, the web's and the one saving an .rrd per decay."""
        s = self.settings
        mode = s.viewer or default_viewer_mode()
        self.emit(ViewerNote(describe_mode(mode, default=s.viewer is None)))
        axis = "roll" if s.axis == "auto" else s.axis
        if mode == "none":
            return [LiveView(mode, axis=axis)]
        web = self._web.stream if self._web is not None else None
        return [
            ViewProcess(
                each,
                axis=axis,
                bind=s.viewer_bind or DEFAULT_BIND,
                spawn_port=s.viewer_port,
                on_note=lambda line: self.emit(ViewerNote(line)),
                rrd_reserve_bytes=s.disk_reserve_bytes,
                web=web if is_web(each) else None,
            )
            for each in (["save", "web"] if mode == "web+save" else [mode])
        ]

    def _make_pipeline(self, driver: MTiDriver) -> DecayPipeline:
        s = self.settings
        metadata, config = self._file_header(driver)
        views = self._make_views()
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
        sinks: list[Sink] = [recording, *(ViewSink(view) for view in views)]
        for view in views:  # the operator's panel on the tablet (--viewer web)
            if isinstance(view, ViewProcess) and view.web is not None:
                sinks.append(LivePanel(view, s.axis, s.angle_deg))
        sinks += self.extra_sinks
        return DecayPipeline(detection, sinks, self.outcomes, fit=LiveFit(identifier))

    # ---- open, feed, retarget, close ----------------------------------------

    def open(self) -> None:
        """Prepare the kernels (no refit compiles mid-decay), open the device, build the pipeline."""
        s = self.settings
        tune_allocator()  # before the view's, rerun's and the fits' threads (acquire.memory)
        prepare_identifier(s.model, self._notice("identifier"))
        if is_web(s.viewer) and self._web is None:  # before the device: a port in use is one line, first
            self._web = open_web_viewer(s.viewer_bind, s.viewer_port, s.viewer_web_port, self.emit)
        driver = self._driver = self._open_device()
        self.status.device = driver.info.describe() if driver.info else s.port
        self.emit(DeviceReady(self.status.device))
        self._pipeline = self._make_pipeline(driver)
        self.status.state = "waiting"

    def feed(self, until: Callable[[], bool]) -> None:
        """Feed the device's blocks to the pipeline until ``until()`` holds or a stop is asked (the blocks
        already read fed first). A device gone mid-way is waited for (``reconnect_timeout_s``); a signal
        while it is away raises KeyboardInterrupt. Between calls the reader reads on: its blocks wait in
        its queue for the next call."""
        driver, pipeline = self._driver, self._pipeline
        assert driver is not None and pipeline is not None, "feed runs between open() and close()"
        while not until() and not self.signals.asked:
            reader = self._reader = self._reader or DeviceReader(driver).start()
            with self.signals.during(
                Phase.FEEDING
            ):  # a signal now ends the loop once the blocks read are fed
                gone = self._stream(pipeline, reader, until)
            if gone is not None:
                self._device_gone(driver, pipeline, str(gone))

    def _stream(
        self, pipeline: DecayPipeline, reader: DeviceReader, until: Callable[[], bool]
    ) -> DeviceGone | None:
        """Feed ``reader``'s blocks to the pipeline until ``until()`` (returns None, the reader left reading)
        or the reader ends: stopped (None; every block read is fed) or the device gone (returns why). Once
        ``runs`` are done the rest is not fed (the reads after the last decay wanted could only start one
        more)."""
        ended = False
        try:
            for item in reader.items(until=lambda: self.signals.asked or self.runs_done()):
                if not isinstance(item, Read):  # the reader ended: stopped, the device gone, or a failure
                    ended = True
                    if isinstance(item.error, DeviceGone) or item.error is None:
                        return item.error
                    raise item.error
                if not self.runs_done():
                    self._feed(pipeline, item)
                if until():
                    return None
            return None
        finally:
            if ended:
                self._reader = None
                reader.close()

    def _feed(self, pipeline: DecayPipeline, read: Read) -> None:
        pipeline.feed(read.block)
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

    def stop_decay(self, ended: DecayEnd) -> None:
        """Close the decay under way as ``ended`` (its file complete with what arrived), the recorder open."""
        if self._pipeline is not None:
            self._pipeline.abort(ended, STOP_NOTES[ended])

    def retarget(self, settings: RecordSettings, run: int) -> None:
        """The next decay's settings (a session's condition: draft, nominal angle and its tolerance, the
        note) and number on the device already streaming; between decays only. On port ``sim`` the
        simulated sensor plays that decay next (``SimulatedMTi.play``): the operator's tilt and release."""
        driver, pipeline, recording = self._driver, self._pipeline, self._recording
        assert driver is not None and pipeline is not None and recording is not None, "between open and close"
        assert pipeline.decay is None, "the condition changes between decays"
        self.hull = settings.check()
        self.settings = settings
        metadata, config = self._file_header(driver)
        recording.run_metadata, recording.run_config = metadata, dict(config)
        recording.draft, recording.nominal_angle_deg = settings.draft, settings.angle_deg
        pipeline.next_run = run
        pipeline.settings = dataclasses.replace(
            pipeline.settings, angle_deg=settings.angle_deg, angle_tolerance_deg=settings.angle_tolerance_deg
        )
        if self.simulator is not None and self.replayed is None:
            self.simulator.play(self.simulation_scenario())

    def close(self, ended: DecayEnd, feed_read: bool = False) -> None:
        """Stop reading (``feed_read``: the blocks read and not yet fed go to the pipeline first, a decay
        under way keeps them), close the decay under way as ``ended`` (its file stays readable), the sinks
        (the viewer), the device. A signal meanwhile never cuts the file being closed."""
        pipeline = self._pipeline
        with self.signals.during(Phase.CLOSING):
            try:
                self._stop_reading(pipeline if feed_read else None)
            finally:
                try:
                    self._shut_down(pipeline, ended)
                finally:
                    self._pipeline = None  # closed: what is said now goes to the listeners given

    def _stop_reading(self, pipeline: DecayPipeline | None) -> None:
        reader, self._reader = self._reader, None
        if reader is None:
            return
        try:
            reader.stop()
            if pipeline is None:
                return
            for item in reader.items(until=lambda: True):
                if isinstance(item, Read) and not self.runs_done():
                    self._feed(pipeline, item)
        finally:
            reader.close()

    def _shut_down(self, pipeline: DecayPipeline | None, ended: DecayEnd) -> None:
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
                try:
                    if self.device is not None:
                        self.device.close()
                finally:
                    web, self._web = self._web, None
                    if web is not None:
                        web.close()
