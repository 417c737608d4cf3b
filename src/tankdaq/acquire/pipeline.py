"""The decay pipeline: samples in, release detection and the live fit, and the sinks that record and show
each decay.

``DecayPipeline`` knows nothing about serial ports or files: the record daemon feeds it blocks from
the driver, replay feeds it blocks re-decoded from a file (``device.driver.StreamBlock`` both). For each
block it runs release detection and the live fit (``acquire.decay.LiveFit``) and tells its sinks
(``acquire.sinks``): every block, a confirmed release (with the pre-trigger from its history of blocks)
and the settle through their hooks; everything said (held, released, a fit, a warning, settled) as one
typed event (``acquire.events``, ``Sink.on_event``). The pipeline alone fans out, one fan-out at a time,
as python-can's ``Notifier``: what the fit and the sinks' hooks return is broadcast once every sink has
heard the current one, never from inside it.

A decay is never lost: whatever a sink or callback raises while a decay is open, every sink is
still told (the file takes the block), then the decay is closed (``ended`` ``DecayEnd.ERROR``,
the file closed with what arrived) before the error is passed on. Every decay ends with a ``DecayEnd``:
settled or timed out by the detector, else as the one who ends it says (``abort``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from functools import partial

from ..device.driver import StreamBlock
from ..physics.models import resolve_model
from ..records import DecayEnd
from ..samples import AXIS_FIELDS
from .decay import LiveDecay, LiveFit
from .events import (
    DecayOutcome,
    Event,
    Held,
    KeptNote,
    KeptOutcomes,
    Note,
    NoteKind,
    PutBack,
    Released,
    Settled,
)
from .memory import release_free_memory
from .release import ReleaseDetector, ReleaseEvent, ReleaseKind
from .sinks import Said, Sink

__all__ = ["HISTORY_S", "DecayOutcome", "DecayPipeline", "DetectionSettings", "PipelineState"]

#: How much history (device seconds) is kept while waiting for a release: the pre-trigger plus
#: the time the detector may need to confirm a release it dates back.
HISTORY_S = 30.0


@dataclass
class DetectionSettings:
    """What release detection needs to know beyond the samples (degrees at this edge)."""

    axis: str = "roll"  # roll, pitch or auto
    angle_deg: float = 8.0
    angle_tolerance_deg: float = 1.0
    pretrigger_s: float = 2.0
    model: str = "ittc-quadratic-restoring"
    detector_settings: dict[str, float] = field(default_factory=dict)


class PipelineState(StrEnum):
    """Where the pipeline is between blocks (the record daemon's status line says it)."""

    WAITING = "waiting"
    HELD = "held"
    DECAYING = "decaying"
    SETTLED = "settled"


class DecayPipeline:
    """Feed ``StreamBlock``s with ``feed``; decays are detected, fitted by ``fit`` (None: not fitted) and
    handed to the ``sinks`` in order, and every sink hears the events (``emit``). ``next_run`` is the
    number the next decay gets (1 first). Every decay's outcome goes into ``outcomes`` (a daemon's own,
    given, outlives its pipelines).
    """

    def __init__(
        self,
        settings: DetectionSettings,
        sinks: Sequence[Sink],
        outcomes: KeptOutcomes | None = None,
        fit: LiveFit | None = None,
    ) -> None:
        self.settings = settings
        self.sinks = list(sinks)
        self.fit = fit
        self.terms = resolve_model(settings.model)
        axes = list(AXIS_FIELDS) if settings.axis == "auto" else [settings.axis]
        self._detectors = {  # fed for as long as the pipeline runs: they keep no list of their events
            axis: ReleaseDetector(axis=axis, keep_events=False, **settings.detector_settings) for axis in axes
        }
        self._history: deque[StreamBlock] = deque()
        self.outcomes = KeptOutcomes() if outcomes is None else outcomes
        self.state = PipelineState.WAITING
        self.held_deg = math.nan
        self.next_run = 1
        self.decay: LiveDecay | None = None  # the decay under way

    # ---- telling the sinks ----------------------------------------

    def _tell(self, call: Callable[[Sink], Said]) -> None:
        """Every sink gets the call, whatever an earlier one raised; then what they returned is broadcast;
        the first failure is raised after."""
        said: list[Event] = []

        def hear(sink: Sink) -> None:
            said.extend(call(sink) or ())

        _each(lambda: _each(*(partial(hear, sink) for sink in self.sinks)), lambda: self.broadcast(said))

    def emit(self, event: Event) -> None:
        """An event for every sink (``Sink.on_event``), whatever an earlier one raised; the decay under way
        keeps its fits and warnings first (``Decay.heard``)."""
        decay = self.decay
        if decay is not None:
            decay.heard(event)
        _each(*(partial(sink.on_event, event) for sink in self.sinks))

    def broadcast(self, events: Iterable[Event]) -> None:
        """Each event for every sink in turn (``emit``), whatever one raised; the first failure after."""
        _each(*(partial(self.emit, event) for event in events))

    # ---- feeding ----------------------------------------

    def feed(self, block: StreamBlock) -> list[DecayOutcome]:
        """Process one block; return the decays it finished.

        Whatever goes wrong while a decay is recorded (a sink, a callback, a bug), its file is
        closed with what arrived before the error is passed on: a decay is never left unfinished.
        """
        try:
            return self._feed(block)
        except Exception as exc:
            self._close_after_error(exc)
            raise

    def _close_after_error(self, exc: Exception) -> None:
        """Close the decay under way with what arrived, saying why; no final fit (the error may be in it).

        Every sink is told even when one fails again (a dead view): the file must close.
        """
        decay, self.decay = self.decay, None
        if decay is None:
            return
        self.state = PipelineState.WAITING
        message = f"recording closed after an error: {type(exc).__name__}: {exc}"
        decay.ended, decay.error = DecayEnd.ERROR, message
        decay.warnings.append(message)
        note = KeptNote(NoteKind.WARNING, message, decay.run, decay.last_t)
        if self.fit is not None:
            with contextlib.suppress(Exception):
                self.fit.finish(decay)  # no final fit after an error: its worker let go
        for sink in self.sinks:  # a sink failing again here is not news: the first error is passed on
            with contextlib.suppress(Exception):
                sink.on_event(note)
            with contextlib.suppress(Exception):
                sink.on_settle(decay)
        outcome = decay.outcome()
        self.outcomes.append(outcome)
        with contextlib.suppress(Exception):  # the error passed on is the first one
            self.emit(Settled(outcome))

    def _feed(self, block: StreamBlock) -> list[DecayOutcome]:
        finished: list[DecayOutcome] = []
        decay = self.decay
        if decay is None:
            self._history.append(block)
            self._trim_history()
        elif block.samples.size:
            decay.last_t = float(block.samples["t"][-1])
        flagged_before = decay is not None and decay.status.flagged_after
        if decay is not None and block.samples.size:
            decay.status.add(block.samples)
        fit = self.fit if decay is not None else None
        _each(
            lambda: self.broadcast(fit.feed(block, decay) if fit is not None and decay is not None else ()),
            lambda: self._tell(lambda sink: sink.on_block(block, decay)),
        )
        if decay is not None and not flagged_before:
            self._note_flagged(decay)
        if block.samples.size == 0:
            return finished
        for axis, detector in self._detectors.items():
            for event in detector.feed(block.samples):
                outcome = self._on_detector_event(axis, event)
                if outcome is not None:
                    finished.append(outcome)
        return finished

    def _trim_history(self) -> None:
        if not self._history:
            return
        newest = self._last_time(self._history[-1])
        while len(self._history) > 1 and newest - self._last_time(self._history[0]) > HISTORY_S:
            self._history.popleft()

    @staticmethod
    def _last_time(block: StreamBlock) -> float:
        return float(block.samples["t"][-1]) if block.samples.size else -math.inf

    def _on_detector_event(self, axis: str, event: ReleaseEvent) -> DecayOutcome | None:
        decay = self.decay
        if decay is not None and axis != decay.axis:
            return None  # the other axis of an auto session moves along; it is not this decay
        if event.kind == ReleaseKind.HELD and decay is None:
            self.state = PipelineState.HELD
            self.held_deg = math.degrees(event.angle_rad - event.baseline_rad)
            self.emit(Held(self.held_deg, axis))
        elif event.kind == ReleaseKind.PUT_BACK and decay is None:
            self.state = PipelineState.WAITING
            self.emit(PutBack())
        elif event.kind == ReleaseKind.RELEASED and decay is None:
            self._start_decay(axis, event)
        elif event.kind == ReleaseKind.SETTLED and decay is not None:
            return self._finish_decay(event.ended or DecayEnd.SETTLED, event.confirmed_t)
        return None

    # ---- one decay ----------------------------------------

    def _start_decay(self, axis: str, event: ReleaseEvent) -> None:
        s = self.settings
        release_t = event.release_t if math.isfinite(event.release_t) else event.t
        angle_deg = math.degrees(event.angle_rad - event.baseline_rad)
        warnings: list[str] = []
        if abs(abs(angle_deg) - s.angle_deg) > s.angle_tolerance_deg:
            warnings.append(
                f"measured initial angle {abs(angle_deg):.2f} deg differs from the nominal "
                f"{s.angle_deg:g} deg by more than {s.angle_tolerance_deg:g} deg"
            )
        blocks = self._pretrigger_blocks(release_t - s.pretrigger_s)
        history = [b.samples for b in self._history if b.samples.size]
        self._history.clear()
        for other in self._detectors.values():
            if other.axis != axis:
                other.reset()
        decay = LiveDecay(
            run=self.next_run,
            axis=axis,
            terms=self.terms,
            release_t=release_t,
            angle_deg=angle_deg,
            release_event=event,
            warnings=list(warnings),
            model=s.model,
            last_t=max([release_t, *(self._last_time(b) for b in blocks)]),
        )
        for samples in history:  # the tilt since the last decay, and what followed the release
            decay.status.add(samples)
        self.decay = decay
        self.state = PipelineState.DECAYING
        self.next_run += 1
        fit = self.fit
        _each(
            lambda: fit.start(decay, blocks) if fit is not None else None,
            lambda: self._tell(lambda sink: sink.on_release(decay, blocks)),
        )
        self.emit(Released(decay.run, angle_deg, axis, release_t, event.release_u95_s))
        for line in warnings:  # said before the run is named; the decay keeps them from the start
            self.emit(Note(NoteKind.WARNING, line, t_s=release_t))
        if tilt := decay.status.describe_before():
            self.emit(Note(NoteKind.NOTE, f"sensor {tilt}", decay.run, release_t))
        self._note_flagged(decay)

    def _note_flagged(self, decay: LiveDecay) -> None:
        """The first samples after the release the sensor flags (clipping, orientation not valid): a warning
        event (the file, the view, a record line) as they arrive; the count goes in the file at settle."""
        tally = decay.status
        if tally.flagged_after:
            text = (
                f"sensor flagged samples {tally.first_after_s:.2f} s after the release (clipping or "
                "orientation not valid): the decay is not clean; those samples are left out of fits"
            )
            self.emit(Note(NoteKind.WARNING, text, decay.run, tally.release_t + tally.first_after_s))

    def _pretrigger_blocks(self, start_t: float) -> list[StreamBlock]:
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
            chosen[0] = dataclasses.replace(head, samples=head.samples[head.carried :], carried=0)
        return chosen

    def _finish_decay(self, ended: DecayEnd, until_t: float = math.inf) -> DecayOutcome:
        """The final fit (of the samples up to ``until_t``, where the detector decided) broadcast (the file
        takes it), then every sink hears the settle (the file closes before the view is told), even when
        one raises (the failure is passed on after, the decay closed)."""
        decay = self.decay
        assert decay is not None
        decay.ended = ended
        self.state = PipelineState.SETTLED
        try:
            if self.fit is not None:
                self.broadcast(self.fit.finish(decay, until_t))
        finally:
            self.decay = None
            try:
                self._tell(lambda sink: sink.on_settle(decay))
            finally:
                outcome = decay.outcome()
                self.outcomes.append(outcome)
        self.emit(Settled(outcome))
        release_free_memory()  # the decay's buffers, freed now, back to the system (acquire.memory)
        return outcome

    def abort(self, ended: DecayEnd, message: str) -> DecayOutcome | None:
        """The decay under way is ended from outside (``ended``: stopped, the stream's end, the device
        gone): ``message`` kept with it, the file closed with what arrived. Detection starts again."""
        decay = self.decay
        for detector in self._detectors.values():
            detector.reset()
        self._history.clear()
        self.state = PipelineState.WAITING
        if decay is None:
            return None
        kind = NoteKind.UNPLUG if ended is DecayEnd.DEVICE_LOST else NoteKind.NOTE
        try:
            self.emit(KeptNote(kind, message, decay.run))
        finally:
            outcome = self._finish_decay(ended)  # closes the file even when the note could not be written
        self.state = PipelineState.WAITING
        return outcome

    def close(self) -> None:
        """Close the decay under way, then every sink (each one, whatever another raised), then the fit. A
        decay still under way here was not ended by its orchestrator (an exception on its way out):
        ``ERROR``."""
        try:
            self.abort(DecayEnd.ERROR, "closed before the decay ended")
        finally:
            try:
                self._tell(lambda sink: sink.close())
            finally:
                if self.fit is not None:
                    self.fit.close()


def _each(*steps: Callable[[], object]) -> None:
    """Every step run, whatever an earlier one raised; the first failure is raised after."""
    failure: Exception | None = None
    for step in steps:
        try:
            step()
        except Exception as exc:
            failure = failure or exc
    if failure is not None:
        raise failure
