"""What a decay pipeline feeds: sinks that listen to blocks, releases, fits, notes and settles.

``DecayPipeline`` detects releases and settles; everything done with a decay is a sink, in the way
python-can's ``Notifier`` hands each message to its listeners and its file logger is one more
listener. The record daemon's pipeline is ``[IdentifierSink, RecordingSink, ViewSink]``; replay is
the same pipeline without the ``RecordingSink``; a guided session adds its own (its level check).

Sinks are told in the order given, and that order is the contract: the identifier comes first (its
final fit must reach the file before the file closes), then the file (the view's .rrd is named
after it, and the file closes before the view is told the run ended), then the view. A sink talks
back through the ``LiveDecay`` it is handed: ``decay.publish(fit)`` and ``decay.note(...)`` reach every
sink at once, on the feeding thread (the file has one writer thread).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import RecordingError, TankdaqError
from ..live.identifier import OnlineIdentifier, OnlineResult
from ..live.worker import REFIT_BUDGET_S, BackgroundFit
from ..records import DecayEnd
from ..samples import AXIS_FIELDS, StatusTally
from ..store.disk import free_bytes, megabytes
from ..store.writer import RecordingWriter
from .events import DecayOutcome, Event

if TYPE_CHECKING:
    from ..viz.live import LiveView
    from ..viz.view_process import ViewProcess
    from .release import ReleaseEvent

#: How long the final fit at settle may compute (CPU time on its worker; it normally takes well under
#: 0.1 s once the kernels are prepared); past it, or past ``FINAL_FIT_WALL_FACTOR`` times it on the wall
#: clock, the file is closed without it and says so.
FINAL_FIT_WAIT_S = 5.0


@dataclass
class Block:
    """One read from the device: the samples it completed and the raw bytes as they arrived."""

    samples: np.ndarray
    raw: bytes
    host_t: float
    carried: int = 0  # leading samples whose bytes are in earlier blocks' raw (the decoder held them)


@dataclass
class LiveDecay:
    """The decay under way, as the pipeline and its sinks share it.

    The pipeline fills in the release; sinks fill in what they made (``path`` by the file, ``rrd_path``
    by the view, ``fit``/``final_fit`` through ``publish``). ``ended`` is set at the end (``ERROR``:
    closed after an exception, with ``error`` saying which).
    """

    run: int
    axis: str
    terms: tuple[str, ...]
    release_t: float
    angle_deg: float  # measured initial angle from the still water (signed)
    release_event: ReleaseEvent
    warnings: list[str]
    publish_fit: Callable[[LiveDecay, OnlineResult], None]
    publish_note: Callable[[LiveDecay, str, str, float | None, Mapping[str, object] | None], None]
    last_t: float = math.nan
    path: Path | None = None
    rrd_path: Path | None = None
    fit: OnlineResult | None = None  # the latest fit published
    final_fit: OnlineResult | None = None
    final_fit_s: float = math.nan
    ended: DecayEnd | None = None  # None while it runs
    error: str = ""
    model: str = ""  # the live model as asked ("auto": chosen by the data); ``terms`` is what it may use
    status: StatusTally = field(init=False)  # the status flags counted as samples arrive (the session's)

    def __post_init__(self) -> None:
        self.status = StatusTally(self.release_t)

    def publish(self, result: OnlineResult) -> None:
        """A fit for every sink (the identifier's refits and its final fit)."""
        self.fit = result
        self.publish_fit(self, result)

    def note(
        self, kind: str, message: str, t_s: float | None = None, data: Mapping[str, object] | None = None
    ) -> None:
        """An event for every sink (a warning, an unplug, a note); warnings are kept for the outcome."""
        if kind == "warning":
            self.warnings.append(message)
        self.publish_note(self, kind, message, t_s, data)

    @property
    def release_message(self) -> str:
        return f"released at {abs(self.angle_deg):.3f} deg"

    def release_data(self) -> dict[str, object]:
        """The release event's data (degrees at this edge)."""
        ev = self.release_event
        return {
            "angle_initial_deg": self.angle_deg,
            "rate_initial_deg_s": math.degrees(ev.rate_rad_s) if math.isfinite(ev.rate_rad_s) else None,
            "still_water_deg": math.degrees(ev.baseline_rad),
            "first_free_sample_t_s": ev.t,
            "release_se_s": ev.release_se_s if math.isfinite(ev.release_se_s) else None,
            "release_u95_s": ev.release_u95_s if math.isfinite(ev.release_u95_s) else None,
        }

    def settle_metadata(self) -> dict[str, object]:
        """What the recording's metadata gains at close: how it ended (``ended``) and the final fit."""
        if self.ended is DecayEnd.ERROR:
            return {"ended": self.ended.value, "error": self.error, **self.status.metadata()}
        extra: dict[str, object] = {
            "ended": self.ended_value,
            "final_fit_s": self.final_fit_s,
            **self.status.metadata(),
        }
        final = self.final_fit
        if final is not None:
            extra.update({f"fit_{k}": v for k, v in final.coefficients.items()})
            extra["fit_r2_angle"] = final.r2_angle
            extra["natural_period_s"] = final.natural_period_s
        return extra

    def outcome(self) -> DecayOutcome:
        """What the decay leaves once it is over: its fit's numbers without the predicted curve (a run
        keeps every outcome: with a curve each, a day of decays at 400 Hz kept about 9 MB an hour)."""
        fit = self.final_fit if self.ended is not DecayEnd.ERROR else self.fit
        return DecayOutcome(
            run=self.run,
            axis=self.axis,
            path=self.path,
            rrd_path=self.rrd_path,
            release_t=self.release_t,
            release_u95_s=self.release_event.release_u95_s,
            angle_initial_deg=self.angle_deg,
            ended=self.ended_value,
            fit=None if fit is None else fit.without_curve(),
            warnings=list(self.warnings),
            status=self.status,
            last_t=self.last_t,
        )

    @property
    def ended_value(self) -> DecayEnd:
        """How it ended, once it has (the pipeline sets ``ended`` before any sink hears the settle)."""
        assert self.ended is not None, "the decay has not ended"
        return self.ended


class Sink:
    """One listener of a decay pipeline; each method does nothing here: a sink overrides what it hears."""

    def on_block(self, block: Block, decay: LiveDecay | None) -> None:
        """Every block fed (``decay``: the decay under way, None while waiting for a release)."""

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[Block]) -> None:
        """A confirmed release, with the blocks since the pre-trigger (the first cut to whole frames)."""

    def on_note(
        self, decay: LiveDecay, kind: str, message: str, t_s: float | None, data: Mapping[str, object] | None
    ) -> None:
        """An event of the decay: a warning, an unplug, a note."""

    def on_fit(self, decay: LiveDecay, result: OnlineResult) -> None:
        """A refit (or the final fit) of the decay."""

    def on_settle(self, decay: LiveDecay) -> None:
        """The decay ended (``decay.ended``; ``ERROR`` after an exception: close, fit nothing)."""

    def on_event(self, event: Event) -> None:
        """What a person would be told (``acquire.events``): a release, a settle, a warning, the device
        gone, the stop. The printer, a guided session and a notebook listen here."""

    def close(self) -> None:
        """The pipeline ends: release what the sink holds."""


class IdentifierSink(Sink):
    """The online identifier: samples after the release go to its worker thread; refits are published.

    ``wait_for_fits`` (replay): each block's refit is done before the next block (the same refits
    every replay); live, a block only hands samples over and finished refits are published at the
    next block. At settle the final fit waits at most ``FINAL_FIT_WAIT_S``. A refit past
    ``refit_budget_s`` is abandoned on the worker (the loop never waits on it) and a warning event
    says so.
    """

    def __init__(
        self,
        identifier: Callable[..., OnlineIdentifier] = OnlineIdentifier,
        wait_for_fits: bool = False,
        refit_budget_s: float = REFIT_BUDGET_S,
    ) -> None:
        self.make_identifier = identifier  # called as identifier(terms, axis=...) at each release
        self.wait_for_fits = wait_for_fits
        self.refit_budget_s = refit_budget_s  # a live refit past it is abandoned (a warning event)
        self._live: BackgroundFit | None = None
        self._implausible: list[str] = []  # the checks the latest fit failed: each said once in a row

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[Block]) -> None:
        identifier = self.make_identifier(decay.model or decay.terms, axis=decay.axis)
        self._live = BackgroundFit(identifier, refit_budget_s=self.refit_budget_s)
        self._implausible = []
        for block in pretrigger:
            self._submit(block, decay)

    def on_block(self, block: Block, decay: LiveDecay | None) -> None:
        if decay is None or self._live is None:
            return
        self._submit(block, decay)
        if self.wait_for_fits:
            self._live.wait_idle(FINAL_FIT_WAIT_S)
        for result in self._live.take():
            self._publish(decay, result)
        self._note_abandoned(self._live, decay)

    def _publish(self, decay: LiveDecay, result: OnlineResult) -> None:
        """The fit to every sink; an implausibility it carries (a check the last fit passed) as a warning
        note: the file's events, the view's event log, the record lines."""
        decay.publish(result)
        about_fit = [f for f in result.findings if not f.about_data]  # the data's flags: the session's note
        new = [f for f in about_fit if f.check not in self._implausible]
        self._implausible = [finding.check for finding in about_fit]
        for finding in new:
            decay.note("warning", f"fit at {result.t_end - decay.release_t:.1f} s: {finding}", result.t_end)

    @staticmethod
    def _note_abandoned(live: BackgroundFit, decay: LiveDecay) -> None:
        """A refit past its budget was abandoned on the worker: the record says so (a warning event)."""
        for line in live.take_notes():
            decay.note("warning", line)

    def _submit(self, block: Block, decay: LiveDecay) -> None:
        assert self._live is not None
        after = block.samples[block.samples["t"] >= decay.release_t] if block.samples.size else block.samples
        if after.size:
            angle_field, rate_field = AXIS_FIELDS[decay.axis]
            excluded = decay.status.unusable(after)
            self._live.submit(
                after["t"].copy(), after[angle_field].copy(), after[rate_field].copy(), excluded
            )

    def on_settle(self, decay: LiveDecay) -> None:
        live, self._live = self._live, None
        if live is None:
            return
        if decay.ended is DecayEnd.ERROR:  # no final fit: the error may be in it
            live.close()
            return
        started = time.perf_counter()
        try:
            refits, final = live.finish(FINAL_FIT_WAIT_S)
        except TankdaqError as exc:  # an unfittable decay (too short, cut by an unplug) is a warning
            self._note_abandoned(live, decay)
            decay.note("warning", f"no final fit: {exc}")
            return
        finally:
            decay.final_fit_s = time.perf_counter() - started
        for result in refits:
            self._publish(decay, result)
        self._note_abandoned(live, decay)
        self._implausible = []  # the final fit's implausibilities are said again: they are the verdict's
        decay.final_fit = final  # before it goes out: a sink tells the final fit from a refit by it
        self._publish(decay, final)

    def close(self) -> None:
        live, self._live = self._live, None
        if live is not None:
            live.close()


class RecordingSink(Sink):
    """One MCAP per decay (``store.writer.RecordingWriter``): opened at the release with the pre-trigger,
    closed at settle with the final fit in its metadata.

    A failed write (disk full) closes the file and raises ``RecordingError``; the file then takes
    nothing more. ``closing_metadata`` is what is known only when a file closes (the driver's counters).
    """

    def __init__(
        self,
        out_dir: Path,
        run_metadata: Mapping[str, object],
        run_config: Mapping[str, object] | None = None,
        draft: float | None = None,
        nominal_angle_deg: float = 8.0,
        closing_metadata: Callable[[], dict[str, object]] = dict,
    ) -> None:
        self.out_dir = out_dir
        self.run_metadata = dict(run_metadata)
        self.run_config = dict(run_config or {})
        self.draft = draft
        self.nominal_angle_deg = nominal_angle_deg
        self.closing_metadata = closing_metadata
        self.writer: RecordingWriter | None = None
        self.paths: list[str] = []  # every file opened, in order (as text: a Path holds 3x the bytes)

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[Block]) -> None:
        from ..store.naming import next_run_number, recording_name

        hull = str(self.run_metadata.get("hull", "hull"))
        draft = self.draft if self.draft is not None else 1.0
        self.out_dir.mkdir(parents=True, exist_ok=True)
        number = next_run_number(self.out_dir, hull, draft, decay.axis)
        name = recording_name(hull, draft, decay.axis, self.nominal_angle_deg, number)
        metadata = {
            **self.run_metadata,
            "axis": decay.axis,
            "run": decay.run,
            "model_terms": ",".join(decay.terms),
            "model": decay.model or ",".join(decay.terms),  # "auto": the refits choose among the terms
        }
        self.writer = RecordingWriter(self.out_dir / name, metadata, self.run_config)
        decay.path = self.writer.path
        self.paths.append(str(self.writer.path))
        for block in pretrigger:
            self._write_block(block)

        def mark_release(writer: RecordingWriter) -> None:
            writer.write_event("release", decay.release_message, decay.release_t, decay.release_data())
            for line in decay.warnings:
                writer.write_event("warning", line, decay.release_t)

        self._write(mark_release)

    def on_block(self, block: Block, decay: LiveDecay | None) -> None:
        if decay is not None:
            self._write_block(block)

    def _write_block(self, block: Block) -> None:
        host_ns = int(block.host_t * 1e9)

        def write(writer: RecordingWriter) -> None:
            writer.write_raw(block.raw, host_ns)
            writer.write_samples(block.samples)
            writer.maybe_flush()

        self._write(write)

    def on_note(
        self, decay: LiveDecay, kind: str, message: str, t_s: float | None, data: Mapping[str, object] | None
    ) -> None:
        self._write(lambda w: w.write_event(kind, message, t_s, data))

    def on_fit(self, decay: LiveDecay, result: OnlineResult) -> None:
        extra = {
            "half_cycles": result.half_cycles,
            "samples": result.n_samples,
            "natural_period_s": result.natural_period_s,
            "offset_deg": math.degrees(result.offset),
            "elapsed_s": result.elapsed_s,
        }
        self._write(
            lambda w: w.write_fit(
                result.t_end, result.coefficients, result.std, result.ci95, result.r2_angle, extra
            )
        )

    def on_settle(self, decay: LiveDecay) -> None:
        ended = decay.ended_value
        said = ended.said(decay.last_t - decay.release_t)

        def close(writer: RecordingWriter) -> None:
            try:
                writer.write_event("settled", f"decay {said}", decay.last_t, {"ended": ended.value})
                writer.update_metadata({**decay.settle_metadata(), **self.closing_metadata()})
            finally:
                writer.close()

        self._write(close)
        self.writer = None

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

    def close(self) -> None:
        writer, self.writer = self.writer, None
        if writer is not None:  # never settled (the pipeline did not close its decay): keep what arrived
            writer.update_metadata({"ended": DecayEnd.ERROR.value})
            writer.close()


class ViewSink(Sink):
    """The live view (``viz.live.LiveView``, or ``viz.view_process.ViewProcess``: the same in a process
    of its own): one run per decay, its .rrd beside the recording.

    Without a recording (replay) the .rrd is named from ``rrd_base``. Before each decay the free space
    is checked: below the view's reserve the decay is shown without an .rrd (a warning; the MCAP
    comes first). The view queues everything on its own thread: a slow or dead viewer costs a note.
    """

    def __init__(self, view: LiveView | ViewProcess, rrd_base: Path | None = None) -> None:
        self.view = view
        self.rrd_base = rrd_base

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[Block]) -> None:
        view = self.view
        rrd = None if decay.path is None else decay.path.with_suffix(".rrd")
        if rrd is None and self.rrd_base is not None:
            suffix = f"-{decay.run}" if decay.run > 1 else ""
            rrd = self.rrd_base.with_name(self.rrd_base.name + suffix + ".rrd")
        short_of_space = None if view.mode == "none" or rrd is None else self._short_of_space(rrd)
        if view.mode == "none" or short_of_space:
            rrd = None
        view.axis = decay.axis
        view.new_run(
            name=decay.path.stem if decay.path else f"run {decay.run}",
            rrd_path=rrd,
            terms=decay.terms,
            time_origin_s=decay.release_t,  # the view reads in seconds since the release
        )
        decay.rrd_path = view.rrd_path
        for block in pretrigger:
            view.log_samples(block.samples)
        view.log_event("release", decay.release_message, decay.release_t)
        for line in decay.warnings:
            view.log_event("warning", line, decay.release_t)
        if short_of_space:
            decay.note("warning", short_of_space, decay.release_t)

    def _short_of_space(self, rrd: Path) -> str | None:
        reserve = self.view.rrd_reserve_bytes
        free = free_bytes(rrd.parent)
        if free >= reserve:
            return None
        return (
            f"only {megabytes(free)} free under {rrd.parent} (keeping {megabytes(reserve)} for recordings): "
            "this decay is recorded without an .rrd; free some space"
        )

    def on_block(self, block: Block, decay: LiveDecay | None) -> None:
        if decay is not None and block.samples.size:
            self.view.log_samples(block.samples)

    def on_note(
        self, decay: LiveDecay, kind: str, message: str, t_s: float | None, data: Mapping[str, object] | None
    ) -> None:
        self.view.log_event(kind, message, t_s)

    def on_fit(self, decay: LiveDecay, result: OnlineResult) -> None:
        t = result.predicted_t
        rate = np.gradient(result.predicted_angle, t) if t.size > 1 else np.zeros_like(result.predicted_angle)
        self.view.log_fit(
            t, result.predicted_angle, rate, result.coefficients, result.ci95, t_fit=result.t_end,
            final=result is decay.final_fit,  # the decay's verdict: never dropped, however far behind
        )  # fmt: skip

    def on_settle(self, decay: LiveDecay) -> None:
        try:
            self.view.log_event("settled", f"decay {decay.ended_value.said()}", decay.last_t)
        finally:
            self.view.end_run()  # the file is closed first (the sink before); the view ends on its thread

    def close(self) -> None:
        self.view.close()
