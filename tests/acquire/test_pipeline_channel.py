"""One channel through the decay pipeline (issue 43 item 2): the pipeline alone fans out, one fan-out at a
time; the live fit returns its fits and the pipeline broadcasts them, so the file holds the final fit
whatever the order of the sinks; a note kept with the decay is neither printed nor streamed; and a stop
signal does what the recorder's phase says."""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

import numpy as np
import pytest

from tankdaq.acquire.decay import LiveDecay, LiveFit
from tankdaq.acquire.events import Event, Fitted, KeptNote, Note, Released, Settled
from tankdaq.acquire.listeners import EventLog
from tankdaq.acquire.pipeline import DecayPipeline, DetectionSettings
from tankdaq.acquire.signals import Phase, SignalStop
from tankdaq.acquire.sinks import RecordingSink, Sink, ViewSink
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import StreamBlock
from tankdaq.records import DecayEnd
from tankdaq.store.reader import read_recording
from tankdaq.viz.live import LiveView

#: The hooks a sink hears the data by: nothing said about a decay may reach a sink from inside one.
HOOKS = {"on_block", "on_release", "on_settle"}


def _inside_a_hook(frame: FrameType | None) -> str | None:
    """The sink hook (``Class.method``) the caller's stack is inside of, None when it is in none."""
    while frame is not None:
        this = frame.f_locals.get("self")
        if frame.f_code.co_name in HOOKS and isinstance(this, Sink):
            return f"{type(this).__name__}.{frame.f_code.co_name}"
        frame = frame.f_back
    return None


class Nesting(Sink):
    """Notes each event it hears that came from inside a sink's hook (a fan-out inside a fan-out)."""

    def __init__(self) -> None:
        self.nested: list[tuple[str, str]] = []
        self.heard: list[Event] = []

    def on_event(self, event: Event) -> None:
        self.heard.append(event)
        hook = _inside_a_hook(sys._getframe(1))
        if hook is not None:
            self.nested.append((type(event).__name__, hook))


@pytest.fixture(scope="module")
def samples() -> np.ndarray:
    samples, _trace = hull_scenario(runs=1, seed=5, rate_hz=100.0).samples()
    return samples


def _run(samples: np.ndarray, sinks: Sequence[Sink]) -> list:
    """The samples in 0.2 s blocks through a pipeline fitting each decay, cut at the stream's end."""
    pipeline = DecayPipeline(DetectionSettings(), sinks, fit=LiveFit(wait_for_fits=True))
    outcomes = []
    try:
        for i in range(0, samples.size, 20):
            outcomes += pipeline.feed(StreamBlock(samples[i : i + 20], b"", 0.0))
        pipeline.abort(DecayEnd.STREAM_ENDED, "end of the samples")
    finally:
        pipeline.close()
    return outcomes


@pytest.mark.slow
def test_no_event_reaches_a_sink_from_inside_another_sinks_hook_and_the_file_holds_the_final_fit(
    samples: np.ndarray, tmp_path: Path
) -> None:
    """The sinks in the order the old contract forbade (the view before the file, a listener first): the
    fits and warnings still come one fan-out at a time, and the file closes with the final fit in it."""
    nesting = Nesting()
    recording = RecordingSink(tmp_path, {"hull": "swath"})
    outcomes = _run(samples, [nesting, ViewSink(LiveView("none")), recording])
    (outcome,) = [o for o in outcomes if o.ended.whole]
    fitted = [e for e in nesting.heard if isinstance(e, Fitted)]
    assert len(fitted) > 3 and [e.final for e in fitted].count(True) == 1 and fitted[-1].final
    assert nesting.nested == [], nesting.nested
    assert outcome.path is not None and outcome.fit is not None
    kept = read_recording(outcome.path)
    assert kept.ended is DecayEnd.SETTLED
    assert float(kept.metadata["fit_b1"]) == pytest.approx(outcome.fit.coefficients["b1"])
    assert len(kept.fits) == len(fitted)  # every fit broadcast went into the file, once
    settled = next(i for i, e in enumerate(nesting.heard) if isinstance(e, Settled))
    released = next(i for i, e in enumerate(nesting.heard) if isinstance(e, Released))
    assert all(released < i < settled for i, e in enumerate(nesting.heard) if isinstance(e, Fitted))


class Unplugged(Sink):
    """Stops nothing itself: notes the decay it hears released, for the test to cut from outside."""

    def __init__(self) -> None:
        self.decay: LiveDecay | None = None

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[StreamBlock]) -> None:
        self.decay = decay


def test_a_note_kept_with_the_decay_goes_in_its_file_and_is_neither_printed_nor_streamed(
    samples: np.ndarray, tmp_path: Path
) -> None:
    log, unplugged = EventLog(), Unplugged()
    recording = RecordingSink(tmp_path, {"hull": "swath"})
    sinks = [recording, unplugged, log]
    pipeline = DecayPipeline(DetectionSettings(), sinks, fit=LiveFit(wait_for_fits=True))
    try:
        for i in range(0, samples.size, 20):
            pipeline.feed(StreamBlock(samples[i : i + 20], b"", 0.0))
            if unplugged.decay is not None:
                break
        outcome = pipeline.abort(DecayEnd.DEVICE_LOST, "the cable came out")
    finally:
        pipeline.close()
    assert outcome is not None and outcome.path is not None and outcome.ended is DecayEnd.DEVICE_LOST
    (kept,) = log.of(KeptNote)
    assert (kept.kind, kept.text, kept.run) == ("unplug", "the cable came out", outcome.run)
    assert not kept.printed and not kept.streamed  # the person heard DeviceLost; a program too
    assert [n for n in log.of(Note) if n.text == "the cable came out"] == [kept]
    events = read_recording(outcome.path).events
    assert [e["message"] for e in events if e["kind"] == "unplug"] == ["the cable came out"]


def test_a_stop_signal_does_what_the_phase_says_and_only_the_first_one_counts() -> None:
    stop = SignalStop()
    assert stop.phase is Phase.STARTING
    with pytest.raises(KeyboardInterrupt):  # nothing recorded yet: at once
        stop(signal.SIGTERM, None)
    assert stop.asked and stop.stopped_by == "SIGTERM"
    stop(signal.SIGINT, None)  # a second signal never cuts a stop, whatever the phase
    assert stop.stopped_by == "SIGTERM"
    for phase in (Phase.FEEDING, Phase.BETWEEN_STEPS, Phase.CLOSING):
        quiet = SignalStop()
        with quiet.during(Phase.BETWEEN_STEPS), quiet.during(phase):
            quiet(signal.SIGHUP, None)  # only asks: the loop, the next step or the closing goes on
            assert quiet.phase is phase
        assert quiet.asked and quiet.stopped_by == "SIGHUP" and quiet.phase is Phase.STARTING
