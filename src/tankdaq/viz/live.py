"""The live rerun view of a decay: angle, rate, the model fitted so far, its coefficients and residual.

One rerun recording per decay (``new_run``), on the device-time timeline ``t``. A refit redraws the
model over the whole decay, and a series that gets new values at old timestamps draws a zig-zag. So
each fit is its own entity (``angle/fits/fit_007``): the newest bold, the one before faint, older ones
fainter. None is ever hidden (``visible_series``): a viewer keeps hidden series in its blueprint across
recordings and restarts, and a later decay's fit of that number would start hidden (a final model never
drawn). Not tankdaq's old ``model/fit_NNN``: a viewer's blueprint may still hide those.

The recording is what must survive, so the view never holds up acquisition: every call
only queues a job for one background thread (``ViewFeed``), sample blocks and refits are
dropped when the thread falls behind, and anything rerun raises (a viewer that died, a
flush that timed out, a full disk under the .rrd) becomes one line for the operator.
"""

from __future__ import annotations

import contextlib
import subprocess
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Self

import numpy as np

from ..errors import InputError
from ..ident.interval_labels import FIT_95
from ..physics.terms import TERM_TABLE
from ..samples import AXIS_FIELDS
from ..store.disk import RESERVE_BYTES, free_bytes, megabytes
from ..store.schemas import interval_pairs
from .view_feed import QUEUE_LIMIT, SAVE_QUEUE_LIMIT, ViewFeed
from .viewer import DEFAULT_BIND, URL_SCHEMES, note_to_stderr, settle_mode, spawn_viewer, url_listening

if TYPE_CHECKING:  # rerun is imported where a view logs, not for --viewer none (0.6 s of start-up)
    import rerun as rr
    import rerun.blueprint as rrb

APPLICATION_ID = "tankdaq"
TIMELINE = "t"
#: At the end of a run rerun gets this long to take what was logged (file and viewer).
FLUSH_TIMEOUT_S = 5.0
#: Closing waits for the view thread's queue while it gets on: it gives up after ``CLOSE_STALL_S`` with no
#: update done (stuck), or ``CLOSE_LIMIT_S`` in all (minutes behind); a slow view finishes its .rrd.
CLOSE_STALL_S = 15.0
CLOSE_LIMIT_S = 120.0


def unfinished_note(what: str, stall_s: float, limit_s: float) -> str:
    """The line for a view closed before it finished: ``what`` names the view and what may be cut."""
    return f"{what} (nothing done for {stall_s:g} s, or {limit_s:g} s in all)"


MEASURED_COLOR = (31, 119, 180)
MODEL_COLOR = (214, 39, 40)
PREVIOUS_COLOR = (150, 150, 150, 140)
EARLIER_COLOR = (110, 110, 110, 70)
INTERVAL_COLOR = (31, 119, 180, 90)
EVENT_LEVELS = {"warning": "WARN", "unplug": "ERROR", "gap": "WARN"}
#: Where each refit's curves go under angle, rate and residual.
FITS = "fits"
#: How a fit is drawn once newer ones came, (colour, width, legend name): the one before the newest, then
#: every older one (one legend entry for all of them).
AGED_STYLES = ((PREVIOUS_COLOR, 1.0, "previous fit"), (EARLIER_COLOR, 0.5, "earlier fits"))


def term_title(term: str) -> str:
    """``b1 (1/s)``: a coefficient named with its unit from the one term table."""
    spec = TERM_TABLE.get(term)
    return f"{term} ({spec.unit})" if spec else term


def decay_blueprint(terms: Sequence[str] = ()) -> rrb.Blueprint:
    """Four plots a person reads without clicking, events underneath; side panels collapsed."""
    import rerun.blueprint as rrb

    if terms:
        coefficients: rrb.Container | rrb.TimeSeriesView = rrb.Grid(
            *(rrb.TimeSeriesView(origin=f"/coefficients/{term}", name=term_title(term)) for term in terms),
            name="Coefficients",
        )
    else:
        coefficients = rrb.TimeSeriesView(origin="/coefficients", name="Coefficients")
    legend = rrb.PlotLegend(corner="RightTop")
    plots = rrb.Grid(
        rrb.TimeSeriesView(origin="/angle", name="Angle (deg)", plot_legend=legend),
        rrb.TimeSeriesView(origin="/rate", name="Rate (deg/s)", plot_legend=legend),
        coefficients,
        rrb.TimeSeriesView(origin="/residual", name="Residual (deg)", plot_legend=legend),
        grid_columns=2,
    )
    return rrb.Blueprint(
        rrb.Vertical(plots, rrb.TextLogView(origin="/events", name="Events"), row_shares=[5, 1]),
        collapse_panels=True,
    )


def set_sinks_with_blueprint(
    rec: rr.RecordingStream, sinks: Sequence[object], blueprint: rrb.Blueprint
) -> None:
    """``rec.set_sinks(*sinks, default_blueprint=blueprint)``, leaving nothing behind.

    rerun 0.41 builds a default blueprint in a stream of its own that it never frees (its memory sink and
    the stream hold each other): two threads and 1.5-2 MB a decay, hundreds of MB over a lab day.
    Built here, the same way, the stream is disconnected once the sinks have taken
    the blueprint, and ``release_recordings`` frees it.
    """
    import rerun as rr
    from rerun.recording_stream import RecordingStream

    bindings = rr.bindings
    stream = RecordingStream._from_native(
        bindings.new_blueprint(
            application_id=APPLICATION_ID, make_default=False, make_thread_default=False, default_enabled=True
        )
    )
    stream.set_time("blueprint", sequence=0)
    blueprint._log_to_stream(stream)
    bindings.set_sinks(
        list(sinks), default_blueprint=stream.memory_recording().storage, recording=rec.to_native()
    )
    stream.disconnect()


def release_recordings() -> None:
    """Free the recordings and blueprint streams nothing holds any more: rerun only disconnects a dropped
    RecordingStream (rerun issue #2116), keeping its threads and buffers, until ``rr.init`` sweeps them."""
    import rerun as rr

    rr.init(APPLICATION_ID, init_logging=False)


class LiveView:
    """Log a decay test to rerun: ``mode`` is spawn, save, none or a rerun URL.

    ``save`` writes one .rrd per run (``rrd_path`` here or in ``new_run``); with spawn or a URL an
    ``rrd_path`` is written as well. ``terms`` gives each coefficient its own plot with its unit. Every
    call returns at once; the logging itself runs on the view's thread (see the module docstring).
    ``on_note`` gets one line per thing the operator should know (viewer started, gone, the .rrd stopped).
    Spawn with no display falls back to save at once; ``mode`` is the mode in effect. ``queue_limit``:
    updates waiting beyond which sample blocks and refits are dropped (default: a few seconds with a
    viewer, ``view_feed.SAVE_QUEUE_LIMIT`` when only saving). ``blueprint``: its recordings' layout.
    """

    blueprint = staticmethod(decay_blueprint)
    _fits = ""  # the fits' entities' prefix under angle/fits (a view of many decays: each one's own)

    def __init__(
        self,
        mode: str = "none",
        rrd_path: str | Path | None = None,
        axis: str = "roll",
        terms: Sequence[str] = (),
        spawn_port: int = 9876,
        bind: str = DEFAULT_BIND,
        on_note: Callable[[str], None] | None = None,
        rrd_reserve_bytes: int = RESERVE_BYTES,
        queue_limit: int | None = None,
    ) -> None:
        self.on_note = on_note or note_to_stderr
        self.mode = settle_mode(mode, axis, self.on_note)
        self.axis = axis
        self.terms = tuple(terms)
        self.spawn_port = spawn_port
        self.bind = bind
        self.rrd_reserve_bytes = rrd_reserve_bytes
        self.queue_limit = queue_limit
        self.viewer_process: subprocess.Popen[bytes] | None = None
        self.rrd_path: Path | None = None
        self._first_rrd_path = None if rrd_path is None else Path(rrd_path)
        self._run_open = False
        self._noted: set[str] = set()
        # state below is touched only by the view thread
        self._live_url: str | None = self.mode if self.mode.startswith(URL_SCHEMES) else None
        self._streaming = False  # this run goes to the viewer at ``_live_url``
        self._rec: rr.RecordingStream | None = None
        self._rrd_writing: Path | None = None
        self._origin = 0.0
        self._feed: ViewFeed | None = None  # started at the first job, ended by close()
        self._dropped_before = 0
        if self.mode != "none":
            # imported here, before a device opens, not by the view thread's first job in the middle
            # of a decay; without a view rerun is never imported (0.6 s of a replay's start-up)
            import rerun  # noqa: F401

        if self.mode == "spawn":
            self._jobs().put(self._spawn_viewer, droppable=False)

    @property
    def dropped(self) -> int:
        """Updates dropped because the view fell behind (the MCAP has them all)."""
        return self._dropped_before + (self._feed.dropped if self._feed else 0)

    def _jobs(self) -> ViewFeed:
        if self._feed is None:
            # a viewer shows the present: a few seconds of backlog at most; a saved .rrd is a file a
            # person opens later: whole, unless the view thread is minutes behind
            limit = self.queue_limit or (SAVE_QUEUE_LIMIT if self.mode == "save" else QUEUE_LIMIT)
            self._feed = ViewFeed(on_error=self._job_failed, limit=limit)
        return self._feed

    # -- the caller's side: queue and return ------------------------------------------------------------

    def _note_once(self, key: str, line: str) -> None:
        if key not in self._noted:
            self._noted.add(key)
            self.on_note(line)

    def _submit(self, job: Callable[[], None], droppable: bool = False) -> None:
        if not self._run_open:
            if self.mode == "save" and self._first_rrd_path is None:
                raise InputError("viewer mode 'save' needs a path for the .rrd file")
            self.new_run(rrd_path=self._first_rrd_path)
        if not self._jobs().put(job, droppable):
            self._note_once("behind", "the view is behind: dropping view updates (the MCAP has every sample)")

    def new_run(
        self,
        name: str = "decay",
        rrd_path: str | Path | None = None,
        terms: Sequence[str] | None = None,
        time_origin_s: float = 0.0,
    ) -> None:
        """Start a fresh recording (one per decay); the previous one is flushed and closed.

        ``time_origin_s`` (device time, e.g. the release) becomes zero on the view's timeline, so a
        person reads "seconds since release" instead of the sensor's hours since power-up.
        """
        if terms is not None:
            self.terms = tuple(terms)
        path = None if rrd_path is None else Path(rrd_path)  # None: no .rrd this run (a low disk)
        self.rrd_path = path
        if self.mode == "none":
            return
        self._run_open = True
        self._noted.discard("behind")
        terms_now, origin = self.terms, float(time_origin_s)
        self._jobs().put(lambda: self._open_run(name, path, terms_now, origin), droppable=False)

    def end_run(self) -> None:
        """Finish the current recording on the view thread (returns at once)."""
        if self._feed is not None and self._run_open:
            self._run_open = False
            self._feed.put(self._end_run, droppable=False)

    def close(self, stall_s: float = CLOSE_STALL_S, limit_s: float = CLOSE_LIMIT_S) -> None:
        """End the run and the view thread (see ``CLOSE_STALL_S``): the .rrd is complete after.

        A spawned viewer stays open: the window belongs to the operator now.
        """
        self.end_run()
        feed, self._feed = self._feed, None
        if feed is not None:
            if not feed.stop(stall_s, limit_s):
                self.on_note(
                    unfinished_note("the view stopped unfinished; the last .rrd may be cut", stall_s, limit_s)
                )
            self._dropped_before += feed.dropped

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def log_samples(self, samples: np.ndarray) -> None:
        """Measured angle and rate of the view's axis, in degrees, against time from the run's origin."""
        if samples.size and self.mode != "none":
            block = samples.copy()
            self._submit(lambda: self._log_samples(block), droppable=True)

    def log_fit(
        self,
        t: np.ndarray,
        predicted_angle: np.ndarray,
        predicted_rate: np.ndarray,
        coefficients: Mapping[str, float],
        ci95: Mapping[str, object] | None = None,
        t_fit: float | None = None,
        final: bool = False,
    ) -> None:
        """A refit: model angle and rate over ``t`` (rad, rad/s), its residual, and the coefficients.

        ``ci95`` per term is [low, high] or a half-width. The coefficients are
        plotted at ``t_fit`` (default: the last time of ``t``) so they converge
        along the same time axis as the decay. A refit is dropped when the view is behind; the
        ``final`` fit of a decay, what the operator judges it by, never is.
        """
        if self.mode != "none":
            args = (np.array(t, dtype=float), np.array(predicted_angle), np.array(predicted_rate))
            fit = (dict(coefficients), dict(ci95 or {}), t_fit)
            self._submit(lambda: self._log_fit(*args, *fit), droppable=not final)

    def log_event(self, kind: str, message: str, t_s: float | None = None) -> None:
        """A run event (release, settled, warning, ...) in the Events panel, at its time."""
        if self.mode != "none":
            self._submit(lambda: self._log_event(kind, message, t_s))

    # -- the view thread's side --------------------------------------------------------------------------

    def _job_failed(self, exc: BaseException) -> None:
        self._note_once(f"failed:{type(exc).__name__}", f"view update failed ({exc}); the recording goes on")
        self._drop_recording()

    def _drop_recording(self) -> None:
        rec, self._rec, self._rrd_writing = self._rec, None, None
        if rec is not None:
            with contextlib.suppress(Exception):  # already reported; nothing more to save of this view
                rec.disconnect()
            del rec
            release_recordings()  # this run's blueprint stream, the runs' recordings dropped before

    def _spawn_viewer(self) -> None:
        """Start the viewer (bound to ``bind``) unless one already listens on the port; else fall back."""
        self.viewer_process, self._live_url = spawn_viewer(self.bind, self.spawn_port, self.on_note)

    def _viewer_gone(self) -> bool:
        """True (once noted) when the spawned viewer has exited: its sink is dropped from then on."""
        process = self.viewer_process
        if self._live_url is None or process is None or process.poll() is None:
            return False
        self.on_note(
            f"the rerun viewer exited (code {process.returncode}); the recording goes on, the .rrd too"
        )
        self._live_url = None
        self._streaming = False
        return True

    def _sinks(self) -> list[rr.GrpcSink | rr.FileSink]:
        import rerun as rr

        sinks: list[rr.GrpcSink | rr.FileSink] = []
        if self._streaming and self._live_url is not None:
            sinks.append(rr.GrpcSink(self._live_url))
        if self._rrd_writing is not None:
            sinks.append(rr.FileSink(str(self._rrd_writing)))
        return sinks

    def _room_for_rrd(self, path: Path) -> bool:
        free = free_bytes(path.parent)
        if free >= self.rrd_reserve_bytes:
            return True
        self.on_note(
            f"only {megabytes(free)} free under {path.parent} (keeping {megabytes(self.rrd_reserve_bytes)} "
            f"for recordings): the .rrd stops here, {path.name} is cut short; the MCAP goes on"
        )
        return False

    def _open_run(self, name: str, rrd_path: Path | None, terms: Sequence[str], origin: float) -> None:
        import rerun as rr

        self._end_run()
        self._viewer_gone()
        self._origin = origin
        self._revision = 0
        self._measured_t: list[np.ndarray] = []
        self._measured_angle: list[np.ndarray] = []
        self._styled_terms: set[str] = set()
        self._rrd_writing = rrd_path if rrd_path is not None and self._room_for_rrd(rrd_path) else None
        self._streaming = self._live_url is not None and url_listening(self._live_url)
        if self._live_url is not None and not self._streaming:
            self.on_note(f"no viewer listening at {self._live_url}: this decay goes to the .rrd only")
        sinks = self._sinks()
        if not sinks:
            return
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        self._rec = rec  # kept referenced: a collected stream closes its sinks
        set_sinks_with_blueprint(rec, sinks, self.blueprint(terms))
        rec.send_recording_name(name)
        for entity in ("angle/measured", "rate/measured"):
            rec.log(
                entity, rr.SeriesLines(colors=[MEASURED_COLOR], widths=[1.5], names=["measured"]), static=True
            )

    def _end_run(self) -> None:
        rec = self._rec
        if rec is None:
            return
        try:
            rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as exc:  # a viewer that died or stalls, a file the disk refused
            self.on_note(self._flush_failed(str(exc)))
        finally:
            self._drop_recording()

    def _flush_failed(self, error: str) -> str:
        """The line for a run whose end rerun could not deliver; a viewer that failed is not used again."""
        if "File-writer" in error:
            return f"the .rrd could not be finished ({error}); the recording goes on"
        if self._streaming:
            self._live_url, self._streaming = None, False
        if "timed out" in error:
            error = f"no answer within {FLUSH_TIMEOUT_S:g} s: stalled or gone"
        return f"the viewer could not take the end of this run ({error}); the recording goes on, .rrd only"

    def _recording(self) -> rr.RecordingStream | None:
        """The stream to log to now, after dropping what cannot take more (a dead viewer, a full disk)."""
        rec = self._rec
        if rec is None:
            return None
        viewer_gone = self._viewer_gone()
        rrd_full = self._rrd_writing is not None and not self._room_for_rrd(self._rrd_writing)
        if rrd_full:
            self._rrd_writing = None
        if viewer_gone or rrd_full:
            sinks = self._sinks()
            if not sinks:
                self._end_run()
                return None
            rec.set_sinks(*sinks)
        return rec

    def _columns(self, rec: rr.RecordingStream, entity: str, t: np.ndarray, values: np.ndarray) -> None:
        import rerun as rr

        rec.send_columns(
            entity,
            indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=float) - self._origin)],
            columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=float)),
        )

    def _log_samples(self, samples: np.ndarray) -> None:
        rec = self._recording()
        if rec is None:
            return
        angle_field, rate_field = AXIS_FIELDS[self.axis]
        self._measured_t.append(samples["t"])
        self._measured_angle.append(samples[angle_field])
        self._columns(rec, "angle/measured", samples["t"], np.degrees(samples[angle_field]))
        self._columns(rec, "rate/measured", samples["t"], np.degrees(samples[rate_field]))

    def _log_fit(
        self,
        t: np.ndarray,
        predicted_angle: np.ndarray,
        predicted_rate: np.ndarray,
        coefficients: Mapping[str, float],
        ci95: Mapping[str, object],
        t_fit: float | None,
    ) -> None:
        import rerun as rr

        rec = self._recording()
        if rec is None:
            return
        self._revision += 1
        fit = f"{self._fits}fit_{self._revision:03d}"
        stamp = float(t[-1]) if t_fit is None else float(t_fit)
        label = f"model (fit {self._revision}, t = {stamp - self._origin:.1f} s)"
        curves = {"angle": (t, np.degrees(predicted_angle)), "rate": (t, np.degrees(predicted_rate))}
        if self._measured_t:
            measured_t = np.concatenate(self._measured_t)
            measured = np.degrees(np.concatenate(self._measured_angle))
            order = np.argsort(measured_t, kind="stable")
            inside = (t >= measured_t.min()) & (t <= measured_t.max())  # no residual against extrapolation
            at_t = np.interp(t[inside], measured_t[order], measured[order])
            curves["residual"] = (t[inside], at_t - curves["angle"][1][inside])
        for group, (times, values) in curves.items():
            name = label if group != "residual" else f"residual (fit {self._revision})"
            rec.log(
                f"{group}/{FITS}/{fit}",
                rr.SeriesLines(colors=[MODEL_COLOR], widths=[2.0], names=[name]),
                static=True,
            )
            self._columns(rec, f"{group}/{FITS}/{fit}", times, values)
            for age, (color, width, aged) in enumerate(AGED_STYLES, start=1):
                if self._revision > age:
                    style = rr.SeriesLines(colors=[color], widths=[width], names=[aged])
                    rec.log(f"{group}/{FITS}/{self._fits}fit_{self._revision - age:03d}", style, static=True)
        rec.set_time(TIMELINE, duration=stamp - self._origin)
        intervals = interval_pairs(coefficients, ci95 or None)
        for term, value in coefficients.items():
            entity = f"coefficients/{term}"
            if term not in self._styled_terms:
                rec.log(
                    entity,
                    rr.SeriesLines(
                        colors=[MEASURED_COLOR, INTERVAL_COLOR, INTERVAL_COLOR],
                        widths=[2.0, 1.0, 1.0],
                        names=[term_title(term), f"{term} {FIT_95} low", f"{term} {FIT_95} high"],
                    ),
                    static=True,
                )
                self._styled_terms.add(term)
            low, high = intervals.get(term, [np.nan, np.nan])
            rec.log(entity, rr.Scalars([float(value), low, high]))

    def _log_event(self, kind: str, message: str, t_s: float | None) -> None:
        import rerun as rr

        rec = self._recording()
        if rec is None:
            return
        if t_s is not None:
            rec.set_time(TIMELINE, duration=float(t_s) - self._origin)
        rec.log("events", rr.TextLog(f"{kind}: {message}", level=EVENT_LEVELS.get(kind, "INFO")))
