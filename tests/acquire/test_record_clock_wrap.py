"""A simulated MTi-630 whose clocks wrap during a decay: one timeline, no lost sample (real pty, real MCAP).

The 600-series SampleTimeFine wraps at 2**32 ticks (119.3 h), PacketCounter at 65536. A recording
must carry both across the wrap: device time keeps rising by one sample period, and the release
is on the unwrapped clock, not at the seconds since the wrap.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.decoding import SampleDecoder
from tankdaq.device.simulator import DeviceIdentity, SimulatedMTi
from tankdaq.store.reader import StoredRecording, iter_raw_chunks, read_recording

TICKS_PER_S = 10_000
RATE_HZ = 100
SAMPLE_TICKS = TICKS_PER_S // RATE_HZ
RELEASE_AFTER_S = 8.0
DECAY_S = 10.0
SPEED = 6.0  # as tests/device/test_device_record.py: the recorder keeps up with 600 frames/s
CLOCK_MODULUS = 1 << 32


@pytest.mark.parametrize(
    ("clock_wrap_s", "counter_wrap_s"),
    [
        (RELEASE_AFTER_S - 1.5, RELEASE_AFTER_S + 2.0),  # the clock wraps in the pre-trigger
        (RELEASE_AFTER_S + 3.0, RELEASE_AFTER_S - 1.0),  # the clock wraps mid-decay
    ],
    ids=["clock-wraps-in-pretrigger", "clock-wraps-mid-decay"],
)
@pytest.mark.slow
def test_a_600_series_recording_is_continuous_across_its_clock_wraps(
    tmp_path: Path, clock_wrap_s: float, counter_wrap_s: float
) -> None:
    start_ticks = CLOCK_MODULUS - round(clock_wrap_s * TICKS_PER_S)
    start_counter = 65536 - round(counter_wrap_s * RATE_HZ)
    (recording,) = _record_630(tmp_path, 1, start_ticks, start_counter)
    ticks = recording.samples["ticks"].astype(np.int64)
    counters = recording.samples["counter"].astype(np.int64)
    # both wraps are inside the recording, and the timeline runs through them a sample at a time
    assert ticks[0] < CLOCK_MODULUS <= ticks[-1], "the recording spans the clock's wrap"
    assert np.any(np.diff(counters) < 0), "the recording spans the counter's wrap"


@pytest.mark.slow
def test_a_600_series_clock_wrapping_between_decays_keeps_one_session_timeline(tmp_path: Path) -> None:
    decay_s = 20.0  # time for decay 1 to settle before the second tilt
    run_s = RELEASE_AFTER_S + decay_s
    start_ticks = CLOCK_MODULUS - round((run_s + 4.5) * TICKS_PER_S)  # after decay 1, before pre-trigger 2
    first, second = _record_630(tmp_path, 2, start_ticks, 0, decay_s)
    assert first.samples["ticks"][-1] < CLOCK_MODULUS <= second.samples["ticks"][0]


def _record_630(
    tmp_path: Path, runs: int, start_ticks: int, start_counter: int, decay_s: float = DECAY_S
) -> list[StoredRecording]:
    """Record ``runs`` decays of a simulated MTi-630 and check each: one continuous timeline, every
    sample there, the release on the unwrapped clock within a sample of the truth."""
    clocks = {"start_ticks": start_ticks, "start_counter": start_counter}
    scenario = hull_scenario(rate_hz=RATE_HZ, runs=runs, seed=5, release_after_s=RELEASE_AFTER_S,
                             decay_s=decay_s, **clocks)  # fmt: skip
    with SimulatedMTi(scenario, speed=SPEED, identity=DeviceIdentity.mti_630()) as sim:
        settings = RecordSettings(port=sim.link, draft=1.0, angle_deg=8.0, hull="swath", rate_hz=RATE_HZ,
                                  out_dir=tmp_path, runs=runs, viewer="none")  # fmt: skip
        outcomes = RecordDaemon(settings).run()
        truths = [r for r in sim.truth if r.kind == "release"]
    assert len(outcomes) == runs == len(truths)
    recordings = [read_recording(outcome.path) for outcome in outcomes]
    for outcome, recording, truth in zip(outcomes, recordings, truths, strict=True):
        assert recording.metadata["product_code"] == "MTi-630-2A8G4"
        ticks = recording.samples["ticks"].astype(np.int64)
        assert np.all(np.diff(ticks) == SAMPLE_TICKS), "device time rises by one sample period"
        assert np.all(np.diff(recording.samples["counter"].astype(np.int64)) % 65536 == 1), "no lost sample"
        assert recording.metadata["link_lost"] == "0"
        # replay decodes the raw channel with the family's modulus from the metadata: the same timeline,
        # up to whole wraps the session made before this file began (its bytes cannot tell them)
        decoder = SampleDecoder.for_device(recording.metadata["product_code"])
        redecoded = np.concatenate([decoder.feed(raw, 0.0)[0] for _, raw in iter_raw_chunks(outcome.path)])
        offset = ticks - redecoded["ticks"].astype(np.int64)
        assert np.all(offset == offset[0]) and offset[0] % CLOCK_MODULUS == 0
        release = next(e for e in recording.events if e["kind"] == "release")
        assert truth.release_s is not None
        true_release_ticks = start_ticks + truth.release_s * TICKS_PER_S
        assert abs(release["t_s"] * TICKS_PER_S - true_release_ticks) <= SAMPLE_TICKS
        assert release["t_s"] - ticks[0] / TICKS_PER_S >= 1.9, "the pre-trigger is kept"
    return recordings
