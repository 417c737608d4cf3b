"""The live fit never holds up acquisition: refits run on their own thread, kernels are ready first.

Real parts: the decay session writes a real MCAP (read back with the reader) from the simulated
sensor's own samples; the held identifier is a real OnlineIdentifier whose refit waits on an
event the test controls; the end-to-end case runs ``tankdaq record --port sim`` in a subprocess
with a fresh numba cache (a first run after install), against the simulator on a real pty.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
from tankdaq.acquire.decay import LiveFit
from tankdaq.acquire.pipeline import DecayPipeline, DetectionSettings
from tankdaq.acquire.sinks import RecordingSink, ViewSink
from tankdaq.config.hulls import load_hull
from tankdaq.device.driver import StreamBlock
from tankdaq.errors import IdentificationError
from tankdaq.live.identifier import OnlineIdentifier, OnlineResult
from tankdaq.live.preparation import prepare_kernels
from tankdaq.live.worker import FINAL_FIT_WALL_FACTOR, BackgroundFit
from tankdaq.records import DecayRun
from tankdaq.store.reader import read_recording
from tankdaq.store.writer import describe_run
from tankdaq.viz.live import LiveView

TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))
TICKS_PER_S = 10_000
#: Generous deadline for a worker to reach the held refit (events, not timings, decide the test).
DEADLINE_S = 120.0


@pytest.fixture(scope="module", autouse=True)
def _kernels_ready() -> None:
    """What the daemon and replay do before a device or file opens (compiling on a first run)."""
    prepare_kernels()


class HeldIdentifier(OnlineIdentifier):
    """The first refit of the decay waits on ``gate`` (the test's event) before fitting."""

    def __init__(self, *args: object, gate: threading.Event, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)
        self.gate = gate
        self.entered = threading.Event()  # the held refit has started
        self.left = threading.Event()  # ... and has returned

    def _refit(self, run: DecayRun, half_cycles: int) -> OnlineResult:
        if self.entered.is_set():
            return super()._refit(run, half_cycles)
        self.entered.set()
        try:
            assert self.gate.wait(DEADLINE_S), "the test never opened the gate"
            return super()._refit(run, half_cycles)
        finally:
            self.left.set()


def _scenario_samples(settings: RecordSettings) -> np.ndarray:
    samples, _trace = RecordDaemon(settings).simulation_scenario().samples()
    return samples


@pytest.mark.slow
def test_a_slow_refit_never_holds_up_the_file_and_its_fit_arrives_once_done(tmp_path: Path) -> None:
    settings = RecordSettings(
        port="sim", hull="swath", draft=1.0, angle_deg=8.0, runs=1, out_dir=tmp_path, sim_seed=0
    )
    samples = _scenario_samples(settings)
    hull = load_hull("swath")
    gate = threading.Event()
    identifiers: list[HeldIdentifier] = []

    def make_identifier(*args: object, **kwargs: object) -> HeldIdentifier:
        identifiers.append(HeldIdentifier(*args, gate=gate, **kwargs))
        return identifiers[-1]

    recording = RecordingSink(
        tmp_path, describe_run("roll", 8.0, hull=hull, draft=1.0, sample_rate_hz=100.0), draft=1.0
    )
    session = DecayPipeline(
        DetectionSettings(), [recording, ViewSink(LiveView("none"))], fit=LiveFit(make_identifier)
    )
    blocks = (samples[i : i + 2] for i in range(0, samples.size, 2))  # 20 ms reads at 100 Hz
    outcomes = []
    try:
        for block in blocks:  # up to the release and the first refit, which is then held
            outcomes += session.feed(StreamBlock(block, b"", 0.0))
            active = session.decay
            if active is not None and block["t"][-1] > active.release_t + 8.0:  # 4 periods: a refit is due
                assert identifiers[0].entered.wait(DEADLINE_S), "the first refit never started"
                break
        else:
            pytest.fail("the decay was not detected")
        (held,) = identifiers
        writer = recording.writer
        assert writer is not None
        written = writer.samples_written
        fed = 0
        for block in blocks:  # 3 s of the decay while the refit is held
            outcomes += session.feed(StreamBlock(block, b"", 0.0))
            fed += block.size
            if fed >= 300:
                break
        assert not held.left.is_set(), "each block returned while the refit was still held"
        assert writer.samples_written == written + fed
        assert active.fit is None  # nothing published yet
        gate.set()
        for block in blocks:
            outcomes += session.feed(StreamBlock(block, b"", 0.0))
            if outcomes:
                break
    finally:
        gate.set()
        session.close()
    (outcome,) = outcomes
    assert outcome.fit is not None and outcome.ended.whole
    recording = read_recording(outcome.path)
    counters = recording.samples["counter"].astype(np.int64)
    assert np.all(np.diff(counters) % 65536 == 1), "every sample reached the file"
    assert len(recording.fits) >= 2
    assert recording.fits[0]["half_cycles"] == held.results_[0].half_cycles, (
        "the held refit, written once done"
    )
    assert recording.fits[-1]["coefficients"] == pytest.approx(outcome.fit.coefficients)


def _held_decay(
    seconds: float,
) -> tuple[threading.Event, HeldIdentifier, BackgroundFit, np.ndarray, np.ndarray, np.ndarray]:
    """A worker whose first refit waits on the returned gate, and a clean decay (period 2 s) to feed it."""
    gate = threading.Event()
    identifier = HeldIdentifier("ittc-linear", gate=gate)
    t = np.arange(0.0, seconds, 0.01)
    angle = 0.1 * np.exp(-0.1 * t) * np.cos(np.pi * t)
    return gate, identifier, BackgroundFit(identifier), t, angle, np.gradient(angle, t)


def test_refits_coalesce_on_the_latest_samples_while_one_runs() -> None:
    gate, identifier, live, t, angle, rate = _held_decay(20.0)
    try:
        for start in range(0, t.size, 2):
            live.submit(t[start : start + 2], angle[start : start + 2], rate[start : start + 2])
            if start == 800:
                assert identifier.entered.wait(DEADLINE_S)
        gate.set()
        refits, final = live.finish(timeout_s=DEADLINE_S)
    finally:
        gate.set()
        live.close()
    # held at the first refit while 12 s of samples arrived: one more refit on all of them, not one per
    # half-cycle missed
    assert len(refits) == 2, [r.half_cycles for r in refits]
    assert refits[-1].n_samples == t.size and final.n_samples == t.size


@pytest.mark.slow
def test_a_final_fit_that_cannot_finish_is_given_up_in_bounded_time() -> None:
    gate, identifier, live, t, angle, rate = _held_decay(8.0)
    try:
        live.submit(t, angle, rate)
        assert identifier.entered.wait(DEADLINE_S)
        # the budget is the worker's CPU time; held outside its solver, it is left at the wall-clock cap
        cap = re.escape(f"{0.1 * FINAL_FIT_WALL_FACTOR:g}")
        with pytest.raises(IdentificationError, match=rf"did not finish within {cap} s"):
            live.finish(timeout_s=0.1)
    finally:
        gate.set()


@pytest.mark.slow
def test_a_first_run_after_install_prepares_the_kernels_before_the_device_and_loses_nothing(
    tmp_path: Path,
) -> None:
    """No kernels built yet (an empty kernel folder): the build happens before the device opens, with
    one line saying so, and leaves the native module for the next run."""
    seed = 5
    out = tmp_path / "rec"
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8", "--runs", "1"]
    args += ["--viewer", "none", "--sim-speed", "8", "--sim-seed", str(seed), "--out", str(out)]
    args += ["--events", "jsonl"]
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "TANKDAQ_KERNEL_DIR": cache}
        done = subprocess.run([TANKDAQ, *args], env=env, capture_output=True, text=True, timeout=600)
        built = list(Path(cache).glob("tankdaq_kernels-*"))
    assert len(built) == 1, built
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.count("preparing the identifier (first run") == 1, done.stderr  # said by the command
    events = [json.loads(line) for line in done.stdout.splitlines()]
    kinds = [event["event"] for event in events]
    assert "device_ready" in kinds and "device_lost" not in kinds, kinds
    building = [e for e in events if e["event"] == "notice" and e["source"] == "identifier"]
    assert building == [], "the kernels were built before the recorder started, not while it streamed"
    (path,) = out.glob("*.mcap")
    recording = read_recording(path)
    counters = recording.samples["counter"].astype(np.int64)
    assert np.all(np.diff(counters) % 65536 == 1), "no packet-counter gap in the decay"
    assert recording.fits, "live and final fits reached the file"
    # the truth: the simulator's scenario for the same settings, as the daemon builds it
    draft = float(recording.run_config["record"]["draft"])
    settings = RecordSettings(port="sim", hull="swath", draft=draft, angle_deg=8.0, runs=1, sim_seed=seed)
    truth = RecordDaemon(settings).simulation_scenario().trace().runs[0]
    release = next(e for e in recording.events if e["kind"] == "release")
    first_free_ticks = round(release["data"]["first_free_sample_t_s"] * TICKS_PER_S)
    ticks = recording.samples["ticks"]
    true_first = int(ticks[np.searchsorted(ticks, truth.release_ticks)])
    assert abs(first_free_ticks - true_first) <= TICKS_PER_S / 100, (first_free_ticks, true_first)
