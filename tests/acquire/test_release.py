"""Release detection against the scenario's truth: one-sample accuracy, no false releases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tankdaq.acquire.release import ReleaseDetector, detect_releases, pick_axis
from tankdaq.config.hulls import hull_scenario
from tankdaq.errors import InputError
from tankdaq.physics.scenario import Handling
from tankdaq.physics.sensor import SensorNoise
from tankdaq.physics.truth import TICKS_PER_S, still_trace
from tankdaq.records import DecayEnd

WITH_PUT_BACKS = Handling(put_back_fraction=0.2)


def _match(events, truth):
    """Each true release paired with the detected release nearest to it (None if missing)."""
    released = [e for e in events if e.kind == "released"]
    pairs = []
    for run in truth:
        near = [e for e in released if abs(e.index - run.release_index) < 50]
        pairs.append((run, near[0] if near else None))
    return pairs, released


def _check_one_sample(rate_hz: float, runs: int, seed: int, **scenario: object) -> None:
    samples, trace = hull_scenario(runs=runs, seed=seed, rate_hz=rate_hz, handling=WITH_PUT_BACKS,
                                   **scenario).samples()  # fmt: skip
    events = ReleaseDetector(axis=trace.axis).fit(samples).events_
    truth = [r for r in trace.runs if r.kind == "release"]
    pairs, released = _match(events, truth)
    assert len(truth) >= runs // 2
    assert all(found is not None for _, found in pairs), "a release was missed"
    assert len(released) == len(truth), "a release was reported that did not happen"
    errors = [found.index - run.release_index for run, found in pairs]
    assert max(abs(e) for e in errors) <= 1, errors
    # The initial angle is measured, not the set one, and well: from the still-water angle, the
    # sensor's mounting bias cancels.
    for run, found in pairs:
        assert found.angle_rad - found.baseline_rad == pytest.approx(run.angle0_rad, abs=math.radians(0.05))
        assert found.confirmed_index > found.index  # decided later, reported at the true first sample
    puts = [e for e in events if e.kind == "put_back"]
    assert len(puts) == sum(r.kind == "put_back" for r in trace.runs)


@pytest.mark.slow
def test_release_within_one_sample_at_100_hz() -> None:
    _check_one_sample(100, runs=40, seed=21)


@pytest.mark.slow
def test_release_within_one_sample_at_400_hz() -> None:
    _check_one_sample(400, runs=40, seed=22)


@pytest.mark.slow
def test_release_within_one_sample_at_other_angles_drafts_and_pitch() -> None:
    _check_one_sample(100, runs=12, seed=23, angle_deg=5.0, draft=0.9)
    _check_one_sample(100, runs=12, seed=24, angle_deg=12.0, draft=1.1)
    _check_one_sample(100, runs=20, seed=32, axis="pitch")


@pytest.mark.slow
def test_heavily_damped_pitch_at_400_hz_mostly_within_one_sample() -> None:
    """Swath pitch (b1 ~ 2) at 400 Hz: one sample is below the gyro noise, so a share, not all.

    Measured 40/40 on this seed (96 % over 160 runs of other seeds; 85 % here and 80 % over those
    before b1 was fitted on the integrated rate instead of the angle sample at the instant).
    """
    samples, trace = hull_scenario(axis="pitch", rate_hz=400, runs=40, seed=33).samples()
    released = [e for e in ReleaseDetector(axis="pitch").fit(samples).events_ if e.kind == "released"]
    pairs, _ = _match(released, trace.runs)
    assert len(released) == len(trace.runs) and all(found is not None for _, found in pairs)
    within = np.mean([abs(found.index - run.release_index) <= 1 for run, found in pairs])
    assert within >= 0.9


def test_settling_follows_the_ittc_threshold() -> None:
    samples, trace = hull_scenario(runs=3, seed=25, decay_s=30).samples()
    events = ReleaseDetector(settle_deg=0.5, settle_window_s=3.0).fit(samples).events_
    settled = [e for e in events if e.kind == "settled"]
    assert len(settled) == 3
    for event, run in zip(settled, trace.runs, strict=True):
        assert event.ended is DecayEnd.SETTLED
        true_amplitude_after = np.abs(np.degrees(trace.angle[event.index : event.index + 300]))
        assert true_amplitude_after.max() < 0.5 + 0.1  # measured with noise and bias, judged on truth
        assert np.abs(np.degrees(trace.angle[event.index - 300 : event.index])).max() > 0.4
        assert event.settle_s == pytest.approx(event.t - event.release_t)
        assert 3.0 < event.settle_s < 30.0
        assert event.release_t == pytest.approx(run.release_s + samples["t"][0], abs=0.01)


def test_streaming_in_blocks_gives_the_same_events_as_offline() -> None:
    samples, _ = hull_scenario(runs=3, seed=26, handling=WITH_PUT_BACKS).samples()
    offline = ReleaseDetector().fit(samples).events_
    detector = ReleaseDetector()
    streamed = []
    rng = np.random.default_rng(0)
    start = 0
    while start < samples.size:
        stop = start + int(rng.integers(1, 120))
        streamed += detector.feed(samples[start:stop])
        start = stop
    assert streamed == offline
    assert {e.kind for e in offline} >= {"held", "released", "settled"}


@pytest.mark.slow
def test_a_reset_detector_forgets_the_rate_it_learnt() -> None:
    """A detector reused on 50 Hz data after 400 Hz data finds every release (it found 1 of 3)."""
    detector = ReleaseDetector()
    fast, _ = hull_scenario(runs=1, seed=3, rate_hz=400).samples()
    detector.fit(fast)
    assert detector.rate_hz is None and detector.rate_hz_ == pytest.approx(400)  # the setting is kept
    slow, trace = hull_scenario(runs=3, seed=4, rate_hz=50).samples()
    reused = [e for e in detector.fit(slow).events_ if e.kind == "released"]
    fresh = [e for e in ReleaseDetector().fit(slow).events_ if e.kind == "released"]
    assert detector.rate_hz_ == pytest.approx(50)
    assert [e.index for e in reused] == [e.index for e in fresh]
    assert len(reused) == sum(r.kind == "release" for r in trace.runs)


@pytest.mark.parametrize("rate_hz", [100, 400])
@pytest.mark.slow
def test_no_false_release_in_an_hour_of_still_water_and_handling(rate_hz: float) -> None:
    """An hour of tilting, holding with tremor and putting back by hand, never letting go."""
    handling = Handling(put_back_fraction=1.0)
    scenario = hull_scenario(runs=110, seed=27, rate_hz=rate_hz, handling=handling, release_after_s=12.0,
                             decay_s=21.0)  # fmt: skip
    assert scenario.duration_s >= 3600
    samples, trace = scenario.samples()
    events = ReleaseDetector().fit(samples).events_
    assert not [e for e in events if e.kind == "released"]
    assert sum(e.kind == "held" for e in events) >= len(trace.runs)


def test_no_false_release_in_still_water_only() -> None:
    """An hour of still water at 100 Hz: no event at all (not even a hold)."""
    still = hull_scenario(runs=0, seed=28).sensor().measure(still_trace(100, "roll", 0, 0, 360_000))
    assert ReleaseDetector().fit(still).events_ == []


def test_pick_axis_finds_the_tilted_one() -> None:
    pitch, _ = hull_scenario(runs=1, axis="pitch", seed=29).samples()
    roll, _ = hull_scenario(runs=1, axis="roll", seed=29).samples()
    assert pick_axis(pitch) == "pitch"
    assert pick_axis(roll) == "roll"
    events = detect_releases(pitch, axis="auto")
    assert [e.kind for e in events if e.kind == "released"] == ["released"]


def test_perfect_data_gives_the_exact_first_free_sample() -> None:
    samples, trace = hull_scenario(runs=4, seed=30, noise=SensorNoise.none(),
                                   handling=Handling(sway_deg=0.0, tremor_deg=0.0)).samples()  # fmt: skip
    released = [e for e in ReleaseDetector().fit(samples).events_ if e.kind == "released"]
    assert [e.index for e in released] == [r.release_index for r in trace.runs]


def test_samples_without_angle_or_rate_do_not_shift_indices() -> None:
    """A message missing an output decodes to NaN; the detector bridges it and keeps counting."""
    samples, trace = hull_scenario(runs=2, seed=31).samples()
    holes = samples.copy()
    rng = np.random.default_rng(1)
    holes["roll"][rng.choice(holes.size, 200, replace=False)] = np.nan
    holes["p"][rng.choice(holes.size, 200, replace=False)] = np.nan
    holes["roll"][:3] = np.nan
    released = [e for e in ReleaseDetector().fit(holes).events_ if e.kind == "released"]
    assert len(released) == 2
    for event, run in zip(released, trace.runs, strict=True):
        assert abs(event.index - run.release_index) <= 1


def test_bad_settings_are_input_errors() -> None:
    with pytest.raises(InputError):
        ReleaseDetector(axis="yaw")
    with pytest.raises(InputError):
        ReleaseDetector().feed_arrays(np.zeros(3), np.zeros(2), np.zeros(3))


@pytest.mark.parametrize("rate_hz", [100, 200, 400])
@pytest.mark.slow
def test_release_instant_is_unbiased_on_the_device_clock_with_its_standard_error(rate_hz: int) -> None:
    """``release_t`` against the true instant (SampleTimeFine ticks / 10 kHz), default tremor and noise.

    24 releases per rate here, 200 in bench/bench_release_bias.py (spread there <= 0.5 sample at 400 Hz,
    so the mean of 24 has a standard error <= 0.1 sample: |mean| < 0.25 sample is 2.5 of them from an
    unbiased estimator, and 22 of 24 within one sample is what a 95 % share gives with probability ~0.9+).
    """
    samples, trace = hull_scenario(runs=24, seed=40 + rate_hz, rate_hz=rate_hz, decay_s=20).samples()
    released = [e for e in ReleaseDetector(axis=trace.axis).fit(samples).events_ if e.kind == "released"]
    pairs, _ = _match(released, trace.runs)
    assert len(released) == len(trace.runs) and all(found is not None for _, found in pairs)
    errors_samples, z = [], []
    for run, found in pairs:
        assert run.release_ticks is not None
        error_s = found.release_t - run.release_ticks / TICKS_PER_S
        errors_samples.append(error_s * rate_hz)
        # between the last held sample and the first free one, with a finite, positive standard error
        assert samples["t"][found.index - 1] < found.release_t <= samples["t"][found.index]
        assert 0 < found.release_se_s < 2.0 / rate_hz
        z.append(error_s / found.release_se_s)
    assert abs(np.mean(errors_samples)) < 0.25, errors_samples
    assert np.mean(np.abs(errors_samples) <= 1) >= 22 / 24, errors_samples
    assert np.mean(np.abs(z) <= 3) >= 0.9, z  # the error is the size the detector says
