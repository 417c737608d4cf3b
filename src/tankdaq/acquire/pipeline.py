"""The decay pipeline: samples in, release detection, and the sinks that record, fit and show each decay.

``DecayPipeline`` knows nothing about serial ports or files: the record daemon feeds it blocks from
the driver, replay feeds it blocks re-decoded from a file. For each block it runs release
detection and tells its sinks (``acquire.sinks``): every block, a confirmed release (with the
pre-trigger from its history of blocks), the notes of the decay, and its settle. What a decay
leaves (an MCAP, a live fit, a view) is made by the sinks; the daemon's pipeline is identifier,
recording, view, replay's the same without the recording. What a person is told (held, released,
a warning, settled) goes to every sink as a typed event (``acquire.events``, ``Sink.on_event``).

A decay is never lost: whatever a sink or callback raises while a decay is open, every sink is
still told (the file takes the block), then the decay is closed (``ended`` ``DecayEnd.ERROR``,
the file closed with what arrived) before the error is passed on. Every decay ends with a ``DecayEnd``:
settled or timed out by the detector, else as the one who ends it says (``abort``).
"""

from __future__ import annotations

import contextlib
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from ..live.identifier import OnlineResult
from ..physics.models import resolve_model
from ..records import DecayEnd
from ..samples import AXIS_FIELDS
from .events import DecayOutcome, Event, Fitted, Held, KeptOutcomes, Note, PutBack, Released, Settled
from .memory import release_free_memory
from .release import ReleaseDetector, ReleaseEvent
from .sinks import Block, LiveDecay, Sink

__all__ = ["HISTORY_S", "Block", "DecayOutcome", "DecayPipeline", "DetectionSettings"]

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


class DecayPipeline:
    """Feed ``Block``s with ``feed``; decays are detected and handed to the ``sinks`` in order, and every
    sink hears the events (``emit``). ``next_run`` is the number the next decay gets (1 first).
    Every decay's outcome goes into ``outcomes`` (a daemon's own, given, outlives its pipelines).
    """

    def __init__(
        self, settings: DetectionSettings, sinks: Sequence[Sink], outcomes: KeptOutcomes | None = None
    ) -> None:
        self.settings = settings
        self.sinks = list(sinks)
        self.terms = resolve_model(settings.model)
        axes = list(AXIS_FIELDS) if settings.axis == "auto" else [settings.axis]
        self._detectors = {  # fed for as long as the pipeline runs: they keep no list of their events
            axis: ReleaseDetector(axis=axis, keep_events=False, **settings.detector_settings) for axis in axes
        }
        self._history: deque[Block] = deque()
        self.outcomes = KeptOutcomes() if outcomes is None else outcomes
        self.state = "waiting"
        self.held_deg = math.nan
        self.next_run = 1
        self.decay: LiveDecay | None = None  # the decay under way

    # ---- telling the sinks ----------------------------------------

    def _tell(self, call: Callable[[Sink], object]) -> None:
        """Every sink gets the call, whatever an earlier one raised; the first failure is raised after."""
        failure: Exception | None = None
        for sink in self.sinks:
            try:
                call(sink)
            except Exception as exc:
                failure = failure or exc
        if failure is not None:
            raise failure

    def emit(self, event: Event) -> None:
        """An event for every sink (``Sink.on_event``), whatever an earlier one raised."""
        self._tell(lambda sink: sink.on_event(event))

    def _publish_fit(self, decay: LiveDecay, result: OnlineResult) -> None:
        self._tell(lambda sink: sink.on_fit(decay, result))
        self.emit(Fitted(decay.run, result))

    def _publish_note(
        self, decay: LiveDecay, kind: str, message: str, t_s: float | None, data: Mapping[str, object] | None
    ) -> None:
        if kind == "warning":  # a warning a sink raises during the decay (an implausible fit) is an event too
            self.emit(Note("warning", message, decay.run))
        self._tell(lambda sink: sink.on_note(decay, kind, message, t_s, data))

    # ---- feeding ----------------------------------------

    def feed(self, block: Block) -> list[DecayOutcome]:
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
        self.state = "waiting"
        message = f"recording closed after an error: {type(exc).__name__}: {exc}"
        decay.ended, decay.error = DecayEnd.ERROR, message
        decay.warnings.append(message)
        for sink in self.sinks:  # a sink failing again here is not news: the first error is passed on
            with contextlib.suppress(Exception):
                sink.on_note(decay, "warning", message, decay.last_t, None)
            with contextlib.suppress(Exception):
                sink.on_settle(decay)
        outcome = decay.outcome()
        self.outcomes.append(outcome)
        with contextlib.suppress(Exception):  # the error passed on is the first one
            self.emit(Settled(outcome))

    def _feed(self, block: Block) -> list[DecayOutcome]:
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
        self._tell(lambda sink: sink.on_block(block, decay))
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
    def _last_time(block: Block) -> float:
        return float(block.samples["t"][-1]) if block.samples.size else -math.inf

    def _on_detector_event(self, axis: str, event: ReleaseEvent) -> DecayOutcome | None:
        decay = self.decay
        if decay is not None and axis != decay.axis:
            return None  # the other axis of an auto session moves along; it is not this decay
        if event.kind == "held" and decay is None:
            self.state = "held"
            self.held_deg = math.degrees(event.angle_rad - event.baseline_rad)
            self.emit(Held(self.held_deg, axis))
        elif event.kind == "put_back" and decay is None:
            self.state = "waiting"
            self.emit(PutBack())
        elif event.kind == "released" and decay is None:
            self._start_decay(axis, event)
        elif event.kind == "settled" and decay is not None:
            return self._finish_decay(event.ended or DecayEnd.SETTLED)
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
            warnings=warnings,
            publish_fit=self._publish_fit,
            publish_note=self._publish_note,
            model=s.model,
            last_t=max([release_t, *(self._last_time(b) for b in blocks)]),
        )
        for samples in history:  # the tilt since the last decay, and what followed the release
            decay.status.add(samples)
        self.decay = decay
        self.state = "decaying"
        self.next_run += 1
        self._tell(lambda sink: sink.on_release(decay, blocks))
        self.emit(Released(decay.run, angle_deg, axis, release_t, event.release_u95_s))
        for line in warnings:
            self.emit(Note("warning", line))
        if tilt := decay.status.describe_before():
            self.emit(Note("note", f"sensor {tilt}", decay.run))
            decay.note("note", f"sensor {tilt}", release_t)
        self._note_flagged(decay)

    def _note_flagged(self, decay: LiveDecay) -> None:
        """The first samples after the release the sensor flags (clipping, orientation not valid): a warning
        event (the file, the view, a record line) as they arrive; the count goes in the file at settle."""
        tally = decay.status
        if tally.flagged_after:
            decay.note(
                "warning",
                f"sensor flagged samples {tally.first_after_s:.2f} s after the release (clipping or "
                "orientation not valid): the decay is not clean; those samples are left out of fits",
                tally.release_t + tally.first_after_s,
            )

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

    def _finish_decay(self, ended: DecayEnd) -> DecayOutcome:
        """The final fit, then the file closed, then the view told: every sink hears the settle even when
        one raises (the failure is passed on after, the decay already closed)."""
        decay, self.decay = self.decay, None
        assert decay is not None
        decay.ended = ended
        self.state = "settled"
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
        gone): ``message`` noted, the file closed with what arrived. Detection starts again."""
        decay = self.decay
        for detector in self._detectors.values():
            detector.reset()
        self._history.clear()
        self.state = "waiting"
        if decay is None:
            return None
        try:
            decay.note("unplug" if ended is DecayEnd.DEVICE_LOST else "note", message)
        finally:
            outcome = self._finish_decay(ended)  # closes the file even when the note could not be written
        self.state = "waiting"
        return outcome

    def close(self) -> None:
        """Close the decay under way, then every sink (each one, whatever another raised). A decay still
        under way here was not ended by its orchestrator (an exception on its way out): ``ERROR``."""
        try:
            self.abort(DecayEnd.ERROR, "closed before the decay ended")
        finally:
            self._tell(lambda sink: sink.close())
