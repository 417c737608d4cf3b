"""What a decay pipeline feeds: sinks that hear the blocks, the decay's release and settle, and its events.

``DecayPipeline`` detects releases and settles and fits each decay (``acquire.decay.LiveFit``);
everything else done with a decay is a sink, in the way python-can's ``Notifier`` hands each message to
its listeners and its file logger is one more listener. The record daemon's sinks are
``[RecordingSink, ViewSink]`` and the listeners given; replay is the same without the ``RecordingSink``;
a guided session adds its own (its level check, its watch).

A sink hears the data through its hooks (``on_block``, ``on_release`` with the pre-trigger, ``on_settle``)
and everything said about it (a fit, a warning, a release for people, the stop) as one typed event
(``on_event``, ``acquire.events``). A sink never calls back into the pipeline: a hook returns what the sink
has to say (the view's warning, the watch's ``ModelMoved``) and the pipeline broadcasts it once every sink
has heard the hook. Sinks are told in the order given; the recording comes before the sinks that read the
path it sets (the view names its .rrd after it; ``CatalogueSink`` reads the file it closed).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..device.driver import StreamBlock
from ..errors import RecordingError
from ..records import DecayEnd
from ..store.disk import free_bytes, megabytes
from ..store.writer import RecordingWriter
from .decay import LiveDecay
from .events import Event, Fitted, Note, NoteKind

if TYPE_CHECKING:
    from ..viz.view_process import View

#: What a hook returns: the events the sink has to say (broadcast after the hook's fan-out), or None.
Said = Iterable[Event] | None


class Sink:
    """One listener of a decay pipeline; each method does nothing here: a sink overrides what it hears."""

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> Said:
        """Every block fed (``decay``: the decay under way, None while waiting for a release)."""
        return None

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[StreamBlock]) -> Said:
        """A confirmed release, with the blocks since the pre-trigger (the first cut to whole frames)."""
        return None

    def on_settle(self, decay: LiveDecay) -> Said:
        """The decay ended (``decay.ended``; ``ERROR`` after an exception: close, fit nothing); its final
        fit, if any, was broadcast before."""
        return None

    def on_event(self, event: Event) -> None:
        """What happened, typed (``acquire.events``): a release, a fit, a warning, a settle, the device
        gone, the stop. The file and the view keep a decay's fits and notes; the printer, a guided
        session and a notebook listen here."""

    def close(self) -> None:
        """The pipeline ends: release what the sink holds."""


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

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[StreamBlock]) -> Said:
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

        self._write(
            lambda w: w.write_event("release", decay.release_message, decay.release_t, decay.release_data())
        )
        return None

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> Said:
        if decay is not None:
            self._write_block(block)
        return None

    def _write_block(self, block: StreamBlock) -> None:
        host_ns = int(block.host_t * 1e9)

        def write(writer: RecordingWriter) -> None:
            writer.write_raw(block.raw, host_ns)
            writer.write_samples(block.samples)
            writer.maybe_flush()

        self._write(write)

    def on_event(self, event: Event) -> None:
        """A fit or a note of the decay goes in its file (nothing is open between decays)."""
        if isinstance(event, Note):
            self._write(lambda w: w.write_event(event.kind, event.text, event.t_s, event.data))
        elif isinstance(event, Fitted):
            self._write_fit(event)

    def _write_fit(self, event: Fitted) -> None:
        result = event.result
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

    def on_settle(self, decay: LiveDecay) -> Said:
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
        return None

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


#: View modes that write no .rrd: no view, or a web view alone (``web+save`` is two views, one saving).
NO_RRD_MODES = ("none", "web")


class ViewSink(Sink):
    """The live view (a ``viz.view_process.View``: ``LiveView``, or ``ViewProcess``, the same in a process
    of its own): one run per decay, its .rrd beside the recording.

    Without a recording (replay) the .rrd is named from ``rrd_base``. Before each decay the free space
    is checked: below the view's reserve the decay is shown without an .rrd (a warning; the MCAP
    comes first). The view queues everything on its own thread: a slow or dead viewer costs a note.
    """

    def __init__(self, view: View, rrd_base: Path | None = None) -> None:
        self.view = view
        self.rrd_base = rrd_base
        self._showing = False  # a decay's run is open in the view

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[StreamBlock]) -> Said:
        view = self.view
        rrd = None if decay.path is None else decay.path.with_suffix(".rrd")
        if rrd is None and self.rrd_base is not None:
            suffix = f"-{decay.run}" if decay.run > 1 else ""
            rrd = self.rrd_base.with_name(self.rrd_base.name + suffix + ".rrd")
        if view.mode in NO_RRD_MODES:
            rrd = None
        short_of_space = None if rrd is None else self._short_of_space(rrd)
        if short_of_space:
            rrd = None
        view.axis = decay.axis
        view.new_run(
            name=decay.path.stem if decay.path else f"run {decay.run}",
            rrd_path=rrd,
            terms=decay.terms,
            time_origin_s=decay.release_t,  # the view reads in seconds since the release
        )
        self._showing = True
        decay.rrd_path = view.rrd_path or decay.rrd_path  # web+save: the saving view's, whichever is first
        for block in pretrigger:
            view.log_samples(block.samples)
        view.log_event("release", decay.release_message, decay.release_t)
        if short_of_space:
            return [Note(NoteKind.WARNING, short_of_space, decay.run, decay.release_t)]
        return None

    def _short_of_space(self, rrd: Path) -> str | None:
        reserve = self.view.rrd_reserve_bytes
        free = free_bytes(rrd.parent)
        if free >= reserve:
            return None
        return (
            f"only {megabytes(free)} free under {rrd.parent} (keeping {megabytes(reserve)} for recordings): "
            "this decay is recorded without an .rrd; free some space"
        )

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> Said:
        if decay is not None and block.samples.size:
            self.view.log_samples(block.samples)
        return None

    def on_event(self, event: Event) -> None:
        """A note or a fit of the decay shown (the final fit is never dropped, however far behind)."""
        if not self._showing:
            return
        if isinstance(event, Note):
            self.view.log_event(event.kind, event.text, event.t_s)
        elif isinstance(event, Fitted):
            result = event.result
            t = result.predicted_t
            angle = result.predicted_angle
            rate = np.gradient(angle, t) if t.size > 1 else np.zeros_like(angle)
            self.view.log_fit(
                t, angle, rate, result.coefficients, result.ci95, t_fit=result.t_end, final=event.final
            )

    def on_settle(self, decay: LiveDecay) -> Said:
        self._showing = False
        try:
            self.view.log_event("settled", f"decay {decay.ended_value.said()}", decay.last_t)
        finally:
            self.view.end_run()  # the file is closed first (the sink before); the view ends on its thread
        return None

    def close(self) -> None:
        self.view.close()
