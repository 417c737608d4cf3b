"""The decay pipeline: samples in, one recording, live fit and view per decay out.

``DecaySession`` knows nothing about serial ports: the record daemon feeds it
blocks from the driver, replay feeds it blocks re-decoded from a file. For each
block it runs release detection; at a confirmed release it opens a recording
that starts a pre-trigger before the release (from its history of blocks),
starts the online identifier, and a view; at settle it writes the final fit and
metadata and closes the file. The identifier refits on its own thread
(``BackgroundFit``): a block only hands it samples, and finished refits are written
from here, the one thread that touches the file.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import Hull
from ..errors import RecordingError, TankdaqError
from ..ident.online import BackgroundFit, OnlineIdentifier, OnlineResult
from ..physics.models import resolve_model
from ..samples import AXIS_FIELDS
from ..store.disk import free_bytes, megabytes
from ..store.writer import RecordingWriter
from ..viz.live import LiveView
from .release import ReleaseDetector, ReleaseEvent

#: How long the final fit at settle may hold the loop (it normally takes well under 0.1 s once the
#: kernels are prepared); past it the file is closed without it and says so.
FINAL_FIT_WAIT_S = 5.0

#: How much history (device seconds) is kept while waiting for a release: the pre-trigger plus
#: the time the detector may need to confirm a release it dates back.
HISTORY_S = 30.0


@dataclass
class Block:
    """One read from the device: the samples it completed and the raw bytes as they arrived."""

    samples: np.ndarray
    raw: bytes
    host_t: float
    carried: int = 0  # leading samples whose bytes are in earlier blocks' raw (the decoder held them)


@dataclass
class SessionSettings:
    """What a decay session needs to know beyond the samples (degrees at this edge)."""

    axis: str = "roll"  # roll, pitch or auto
    angle_deg: float = 8.0
    angle_tolerance_deg: float = 1.0
    pretrigger_s: float = 2.0
    model: str = "ittc-quadratic-restoring"
    out_dir: Path | None = Path("recordings")  # None: do not write (replay)
    rrd_base: Path | None = None  # where .rrd files go when not beside a recording (replay)
    hull: Hull | None = None
    draft: float | None = None
    run_metadata: dict[str, object] = field(default_factory=dict)
    run_config: dict[str, object] = field(default_factory=dict)
    detector_settings: dict[str, float] = field(default_factory=dict)
    #: Metadata known only when a file closes (the driver's link counters), added to it then.
    closing_metadata: Callable[[], dict[str, object]] = dict
    # replay: each block's refit is done before the next block (nothing is lost by waiting, and the
    # refits are the same every time); live, the read loop never waits for a fit
    wait_for_fits: bool = False


@dataclass
class DecayOutcome:
    """What one recorded decay left behind."""

    run: int
    axis: str
    path: Path | None
    rrd_path: Path | None
    release_t: float
    angle_initial_deg: float
    settle_reason: str
    fit: OnlineResult | None
    warnings: list[str]


class DecaySession:
    """Feed ``Block``s with ``feed``; decays are detected, recorded, fitted and shown.

    ``view`` is a LiveView (mode none for no viewer). ``on_event`` receives one
    line of text per thing a person wants to know (release, settle, warnings, file).
    """

    def __init__(
        self,
        settings: SessionSettings,
        view: LiveView,
        on_event: Callable[[str], None] | None = None,
        identifier: Callable[..., OnlineIdentifier] = OnlineIdentifier,
    ) -> None:
        self.settings = settings
        self.view = view
        self.on_event = on_event or (lambda _line: None)
        self.make_identifier = identifier  # called as identifier(terms, axis=...) at each release
        self.terms = resolve_model(settings.model)
        axes = list(AXIS_FIELDS) if settings.axis == "auto" else [settings.axis]
        self._detectors = {axis: ReleaseDetector(axis=axis, **settings.detector_settings) for axis in axes}
        self._history: deque[Block] = deque()
        self._samples_fed = 0
        self.outcomes: list[DecayOutcome] = []
        self.state = "waiting"
        self.held_deg = math.nan
        self._run_no = 0
        self._active: _ActiveDecay | None = None

    # ---- feeding ----------------------------------------

    def feed(self, block: Block) -> list[DecayOutcome]:
        """Process one block; return the decays it finished.

        Whatever goes wrong while a decay is recorded (a view, an identifier, a bug), its file is
        closed with what arrived before the error is passed on: a decay is never left unfinished.
        """
        try:
            return self._feed(block)
        except Exception as exc:
            self._close_after_error(exc)
            raise

    def _close_after_error(self, exc: Exception) -> None:
        active, self._active = self._active, None
        if active is None:
            return
        self.state = "waiting"
        outcome = active.close_after_error(exc)
        self.outcomes.append(outcome)
        self.on_event(active.summary(outcome))

    def _feed(self, block: Block) -> list[DecayOutcome]:
        finished: list[DecayOutcome] = []
        if self._active is not None:
            self._active.append(block)
        else:
            self._history.append(block)
            self._trim_history()
        if block.samples.size == 0:
            if self._active is not None:
                self._active.idle()
            return finished
        for axis, detector in self._detectors.items():
            for event in detector.feed(block.samples):
                outcome = self._on_detector_event(axis, event)
                if outcome is not None:
                    finished.append(outcome)
        self._samples_fed += block.samples.size
        return finished

    def _trim_history(self) -> None:
        if not self._history:
            return
        newest = self._last_time(self._history[-1])
        while len(self._history) > 1 and newest - self._last_time(self._history[0]) > HISTORY_S:
            self._history.popleft()

    @staticmethod
    def _last_time(block: Block) -> float:
        return float(block.samples["t"][-1]) if block.samples.size else -math.inf

    def _on_detector_event(self, axis: str, event: ReleaseEvent) -> DecayOutcome | None:
        active = self._active
        if active is not None and axis != active.axis:
            return None  # the other axis of an auto session moves along; it is not this decay
        if event.kind == "held" and active is None:
            self.state = "held"
            self.held_deg = math.degrees(event.angle_rad - event.baseline_rad)
            self.on_event(f"held at {self.held_deg:+.2f} deg ({axis})")
        elif event.kind == "put_back" and active is None:
            self.state = "waiting"
            self.on_event("put back without a release")
        elif event.kind == "released" and active is None:
            self._start_decay(axis, event)
        elif event.kind == "settled" and active is not None:
            return self._finish_decay(event.reason or "amplitude")
        return None

    # ---- one decay ----------------------------------------

    def _start_decay(self, axis: str, event: ReleaseEvent) -> None:
        s = self.settings
        self._run_no += 1
        release_t = event.release_t if math.isfinite(event.release_t) else event.t
        angle_deg = math.degrees(event.angle_rad - event.baseline_rad)
        warnings: list[str] = []
        if abs(abs(angle_deg) - s.angle_deg) > s.angle_tolerance_deg:
            warnings.append(
                f"measured initial angle {abs(angle_deg):.2f} deg differs from the nominal "
                f"{s.angle_deg:g} deg by more than {s.angle_tolerance_deg:g} deg"
            )
        blocks = self._pretrigger_blocks(release_t - s.pretrigger_s)
        self._history.clear()
        for other in self._detectors.values():
            if other.axis != axis:
                other.reset()
        self._active = _ActiveDecay(self, axis, self._run_no, release_t, angle_deg, event, warnings)
        self._active.begin(blocks)
        self.state = "decaying"
        self.on_event(
            f"run {self._run_no}: released at {abs(angle_deg):.2f} deg ({axis}), t = {release_t:.3f} s"
        )
        for line in warnings:
            self.on_event(f"warning: {line}")

    def _pretrigger_blocks(self, start_t: float) -> list[Block]:
        """The history from the block holding ``start_t`` on, the first one cut to whole frames."""
        blocks = list(self._history)
        first = 0
        for i, block in enumerate(blocks):
            if block.samples.size and float(block.samples["t"][-1]) >= start_t:
                first = i
                break
        chosen = blocks[first:]
        if chosen and chosen[0].carried:  # the file's raw bytes must hold every sample it stores
            head = chosen[0]
            chosen[0] = Block(head.samples[head.carried :], head.raw, head.host_t)
        return chosen

    def _finish_decay(self, reason: str) -> DecayOutcome:
        active, self._active = self._active, None
        assert active is not None
        outcome = active.finish(reason)  # closes its file whatever happens
        self.outcomes.append(outcome)
        self.state = "settled"
        self.on_event(active.summary(outcome))
        return outcome

    def abort(self, kind: str, message: str) -> DecayOutcome | None:
        """The stream ended mid-decay (unplug, Ctrl-C): close the file with what arrived."""
        active = self._active
        for detector in self._detectors.values():
            detector.reset()
        self._history.clear()
        self.state = "waiting"
        if active is None:
            return None
        self._active = None
        try:
            active.event(kind, message)
        finally:
            outcome = active.finish(kind)  # closes the file even when the event could not be written
        self.outcomes.append(outcome)
        self.on_event(active.summary(outcome))
        return outcome

    def close(self) -> None:
        self.abort("note", "session closed")
        self.view.close()


class _ActiveDecay:
    """The recording, identifier and view of the decay under way."""

    def __init__(
        self,
        session: DecaySession,
        axis: str,
        run: int,
        release_t: float,
        angle_deg: float,
        event: ReleaseEvent,
        warnings: list[str],
    ) -> None:
        self.session = session
        self.axis = axis
        self.run = run
        self.release_t = release_t
        self.angle_deg = angle_deg
        self.release_event = event
        self.warnings = warnings
        self.fit: OnlineResult | None = None
        self._last_t = release_t
        self.writer: RecordingWriter | None = None
        self.path: Path | None = None
        self.rrd_path: Path | None = None
        self.live_fit = BackgroundFit(session.make_identifier(session.terms, axis=axis))

    def _open(self) -> None:
        """Open the recording, then the view (its .rrd is named after the recording)."""
        s = self.session.settings
        session = self.session
        if s.out_dir is not None:
            self._open_writer()
        rrd = None if self.path is None else self.path.with_suffix(".rrd")
        if rrd is None and s.rrd_base is not None:
            rrd = s.rrd_base.with_name(s.rrd_base.name + (f"-{self.run}" if self.run > 1 else "") + ".rrd")
        if session.view.mode == "none" or (rrd is not None and not self._room_for_rrd(rrd)):
            rrd = None
        session.view.axis = self.axis
        session.view.new_run(
            name=self.path.stem if self.path else f"run {self.run}",
            rrd_path=rrd,
            terms=session.terms,
            time_origin_s=self.release_t,  # the view reads in seconds since the release
        )
        self.rrd_path = session.view.rrd_path

    def _room_for_rrd(self, rrd: Path) -> bool:
        """Free space checked before each decay: below the reserve, no .rrd (the MCAP comes first)."""
        reserve = self.session.view.rrd_reserve_bytes
        free = free_bytes(rrd.parent)
        if free >= reserve:
            return True
        line = (
            f"only {megabytes(free)} free under {rrd.parent} (keeping {megabytes(reserve)} for recordings): "
            "this decay is recorded without an .rrd; free some space"
        )
        self.warnings.append(line)
        return False

    def _open_writer(self) -> None:
        from ..store.naming import next_run_number, recording_name

        s = self.session.settings
        hull = s.hull.name if s.hull else str(s.run_metadata.get("hull", "hull"))
        draft = s.draft if s.draft is not None else 1.0
        assert s.out_dir is not None
        s.out_dir.mkdir(parents=True, exist_ok=True)
        number = next_run_number(s.out_dir, hull, draft, self.axis)
        name = recording_name(hull, draft, self.axis, s.angle_deg, number)
        metadata = dict(s.run_metadata)
        metadata.update({"axis": self.axis, "run": self.run, "model_terms": ",".join(self.session.terms)})
        self.writer = RecordingWriter(s.out_dir / name, metadata, s.run_config)
        self.path = self.writer.path

    def begin(self, blocks: list[Block]) -> None:
        """Open the file and view, write the pre-trigger history, mark the release, feed the identifier."""
        self._open()
        for block in blocks:
            self.append(block)
        ev = self.release_event
        self.event(
            "release",
            f"released at {abs(self.angle_deg):.3f} deg",
            self.release_t,
            {
                "angle_initial_deg": self.angle_deg,
                "rate_initial_deg_s": math.degrees(ev.rate_rad_s) if math.isfinite(ev.rate_rad_s) else None,
                "still_water_deg": math.degrees(ev.baseline_rad),
                "first_free_sample_t_s": ev.t,
            },
        )
        for line in self.warnings:
            self.event("warning", line, self.release_t)

    def _write(self, action: Callable[[RecordingWriter], object]) -> None:
        """Do ``action`` on the file; a failed write (disk full) closes it and stops the recording."""
        if self.writer is None:
            return
        try:
            action(self.writer)
        except RecordingError:
            self.writer.close()
            self.writer = None
            raise

    def append(self, block: Block) -> None:
        """Write a block to the file and view; samples after the release go to the identifier."""
        host_ns = int(block.host_t * 1e9)

        def write(writer: RecordingWriter) -> None:
            writer.write_raw(block.raw, host_ns)
            writer.write_samples(block.samples)
            writer.maybe_flush()

        self._write(write)
        if block.samples.size:
            self._last_t = float(block.samples["t"][-1])
            self.session.view.log_samples(block.samples)
            after = block.samples[block.samples["t"] >= self.release_t]
            if after.size:
                angle_field, rate_field = AXIS_FIELDS[self.axis]
                self.live_fit.submit(after["t"].copy(), after[angle_field].copy(), after[rate_field].copy())
        if self.session.settings.wait_for_fits:
            self.live_fit.wait_idle(FINAL_FIT_WAIT_S)
        self._publish(self.live_fit.take())

    def idle(self) -> None:
        self._write(lambda writer: writer.maybe_flush())
        self._publish(self.live_fit.take())

    def _publish(self, results: list[OnlineResult]) -> None:
        for result in results:
            self._on_fit(result)

    def event(
        self, kind: str, message: str, t_s: float | None = None, data: Mapping[str, object] | None = None
    ):
        self._write(lambda writer: writer.write_event(kind, message, t_s, data))
        self.session.view.log_event(kind, message, t_s)

    def _on_fit(self, result: OnlineResult) -> None:
        self.fit = result
        rate = (
            np.gradient(result.predicted_angle, result.predicted_t) if result.predicted_t.size > 1 else None
        )
        self.session.view.log_fit(
            result.predicted_t,
            result.predicted_angle,
            rate if rate is not None else np.zeros_like(result.predicted_angle),
            result.coefficients,
            result.ci95,
            t_fit=result.t_end,
        )
        self._write(
            lambda writer: writer.write_fit(
                result.t_end,
                result.coefficients,
                result.std,
                result.ci95,
                result.r2_angle,
                {
                    "half_cycles": result.half_cycles,
                    "samples": result.n_samples,
                    "natural_period_s": result.natural_period_s,
                    "offset_deg": math.degrees(result.offset),
                    "elapsed_s": result.elapsed_s,
                },
            )
        )

    def finish(self, reason: str) -> DecayOutcome:
        """The final fit, then close the file: closed even when the fit or the view raise."""
        started = time.perf_counter()
        final: OnlineResult | None = None
        try:
            final = self._final_fit()
            self.session.view.log_event("settled", f"decay ended ({reason})", self._last_t)
        finally:
            extra: dict[str, object] = {"settle_reason": reason, "final_fit_s": time.perf_counter() - started}
            if final is not None:
                extra.update({f"fit_{k}": v for k, v in final.coefficients.items()})
                extra["fit_r2_angle"] = final.r2_angle
                extra["natural_period_s"] = final.natural_period_s
            self._close_file(reason, extra)
        self.session.view.end_run()  # the file is closed first; the view finishes on its own thread
        return self._outcome(reason, final)

    def _final_fit(self) -> OnlineResult | None:
        try:
            refits, final = self.live_fit.finish(FINAL_FIT_WAIT_S)
        except TankdaqError as exc:  # an unfittable decay (too short, cut by an unplug) is a warning
            self.warnings.append(f"no final fit: {exc}")
            self.event("warning", f"no final fit: {exc}")
            return None
        self._publish([*refits, final])
        return final

    def close_after_error(self, exc: Exception) -> DecayOutcome:
        """Close the file with what arrived, saying why; no final fit (the error may be in it)."""
        self.live_fit.close()
        message = f"recording closed after an error: {type(exc).__name__}: {exc}"
        self.warnings.append(message)
        try:
            self._write(lambda writer: writer.write_event("warning", message, self._last_t))
        finally:
            self._close_file("error", {"settle_reason": "error", "error": message})
        return self._outcome("error", self.fit)

    def _close_file(self, reason: str, extra: dict[str, object]) -> None:
        def close(writer: RecordingWriter) -> None:
            try:
                writer.write_event("settled", f"decay ended ({reason})", None, {"reason": reason})
                writer.update_metadata({**extra, **self.session.settings.closing_metadata()})
            finally:
                writer.close()

        self._write(close)
        self.writer = None

    def _outcome(self, reason: str, final: OnlineResult | None) -> DecayOutcome:
        return DecayOutcome(
            run=self.run,
            axis=self.axis,
            path=self.path,
            rrd_path=self.rrd_path,
            release_t=self.release_t,
            angle_initial_deg=self.angle_deg,
            settle_reason=reason,
            fit=final,
            warnings=list(self.warnings),
        )

    def summary(self, outcome: DecayOutcome) -> str:
        fit = outcome.fit
        coeffs = "  ".join(f"{k}={v:.4g}" for k, v in fit.coefficients.items()) if fit else "no fit"
        where = f" -> {outcome.path}" if outcome.path else ""
        period = f", T0 {fit.natural_period_s:.3f} s, R2 {fit.r2_angle:.4f}" if fit else ""
        return f"run {outcome.run}: {outcome.settle_reason}; {coeffs}{period}{where}"
