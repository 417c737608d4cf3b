"""What a recorder fed for a lab day keeps per decay (issue 22 item 8; the figure is bench_memory_day.py):
no predicted curve in a finished decay's outcome, no list of every release event in its detectors."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tankdaq.acquire.pipeline import Block, DecayPipeline, DetectionSettings
from tankdaq.acquire.release import ReleaseDetector
from tankdaq.acquire.sinks import Decay, IdentifierSink, Sink
from tankdaq.config import hull_scenario
from tankdaq.ident.online import OnlineResult

RUNS = 3


def _samples() -> np.ndarray:
    samples, _trace = hull_scenario(runs=RUNS, seed=5, rate_hz=100.0).samples()
    return samples


class FinalFits(Sink):
    """The last fit published in each decay, as the sinks saw it (curve included)."""

    def __init__(self) -> None:
        self.last: dict[int, OnlineResult] = {}

    def on_fit(self, decay: Decay, result: OnlineResult) -> None:
        self.last[decay.run] = result

    def on_note(
        self, decay: Decay, kind: str, message: str, t_s: float | None, data: Mapping[str, object] | None
    ) -> None:
        """Notes are not what this sink listens for."""


def test_a_finished_decay_keeps_its_fit_without_the_curve_and_the_detector_no_event_list() -> None:
    samples = _samples()
    fits = FinalFits()
    pipeline = DecayPipeline(DetectionSettings(), [IdentifierSink(wait_for_fits=True), fits])
    outcomes = []
    try:
        for i in range(0, samples.size, 20):  # 0.2 s reads at 100 Hz
            outcomes += pipeline.feed(Block(samples[i : i + 20], b"", 0.0))
    finally:
        pipeline.close()
    finished = [o for o in outcomes if o.settle_reason in ("amplitude", "timeout")]
    assert len(finished) == RUNS
    for outcome in finished:
        assert outcome.fit is not None
        published = fits.last[outcome.run]
        assert published.predicted_t.size > 1000, "the sinks saw the whole curve"
        assert outcome.fit.predicted_t.size == 0 and outcome.fit.predicted_angle.size == 0
        assert outcome.fit.coefficients == published.coefficients
        assert outcome.fit.n_samples == published.n_samples
    assert all(detector.events_ == [] for detector in pipeline._detectors.values())


def test_a_detector_that_keeps_no_events_returns_the_same_ones() -> None:
    samples = _samples()
    offline = ReleaseDetector().fit(samples).events_
    live = ReleaseDetector(keep_events=False)
    returned = [event for i in range(0, samples.size, 37) for event in live.feed(samples[i : i + 37])]
    assert [e.kind for e in offline].count("released") == RUNS
    assert [(e.kind, e.index) for e in returned] == [(e.kind, e.index) for e in offline]
    assert live.events_ == []
