"""No fit can hang the recorder (issue 19): bounded kernels that release the interpreter lock, a solver
that stops at its budget, a live refit past its budget abandoned while the file goes on.

Real parts only: the native module and numba's JIT of the same kernels, the real Levenberg-Marquardt,
the real OnlineIdentifier on a worker, the real decay pipeline writing a real MCAP read back with the
official ``mcap`` reader. The runaway is a real input: the simulated swath decay with its gyro read
1000 times too large (a rate in mrad/s taken for rad/s), which the model cannot follow: one fit of its
first 10 s takes 7 s where a refit takes 10-50 ms, and longer as the decay grows (bench/bench_runaway.py),
or a made-up start with an absurd damping (1000 sub-steps per sample in every evaluation).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
from tankdaq.acquire.decay import LiveFit
from tankdaq.acquire.pipeline import DecayPipeline, DetectionSettings
from tankdaq.acquire.sinks import RecordingSink, ViewSink
from tankdaq.config.hulls import load_hull
from tankdaq.device.driver import StreamBlock
from tankdaq.errors import IdentificationError
from tankdaq.ident import compiled, kernels
from tankdaq.ident.least_squares import FitAbandoned, levenberg_marquardt, solve_budget
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.live.identifier import OnlineIdentifier
from tankdaq.live.preparation import prepare_kernels
from tankdaq.live.worker import BackgroundFit
from tankdaq.records import DecayRun
from tankdaq.store.reader import read_recording
from tankdaq.store.writer import describe_run
from tankdaq.viz.live import LiveView

#: Generous bound for a worker to reach a state (conditions, not timings, decide each test).
DEADLINE_S = 120.0
#: The gyro read in mrad/s as if rad/s.
GYRO_SCALE = 1000.0


@pytest.fixture(scope="module", autouse=True)
def _kernels_ready() -> None:
    prepare_kernels()


@pytest.fixture(scope="module", params=["native", "jit"])
def source(request: pytest.FixtureRequest) -> Any:
    """The module the kernels are called from: the native one (built here if missing) or numba's JIT."""
    if request.param == "jit":
        return kernels
    assert compiled.ensure_native() is None, "the native kernels could not be built here"
    native = compiled.load_native(compiled.native_path())
    assert native is not None
    return native


def _decay_t(seconds: float, rate_hz: float = 100.0) -> np.ndarray:
    return np.arange(0.0, seconds, 1.0 / rate_hz)


@pytest.mark.slow
def test_an_exploding_simulation_stops_at_once_with_ok_false_and_finite_outputs(source: Any) -> None:
    t = _decay_t(200.0)
    codes = compiled.term_codes(("b1", "c1"))
    theta = np.array([-50.0, 1.0])  # negative damping: e^(50 t)
    x, v, sx, sv, ok = source.simulate_with_sensitivities(
        t, 0.1, 0.0, theta, codes, np.zeros_like(t), np.zeros((t.size, 0)), 1e-3, 1
    )
    assert not ok
    assert all(np.all(np.isfinite(a)) for a in (x, v, sx, sv))
    assert np.max(np.abs(x)) <= kernels.MAX_ANGLE_RAD and np.max(np.abs(v)) <= kernels.MAX_RATE_RAD_S
    held = int(np.argmax(np.all(sx == 0.0, axis=1)))  # where integration stopped: the rest is held
    assert 0 < held < 100, "stopped within the first second, not after 200 s of integration"
    assert np.all(x[held:] == x[held - 1]) and np.all(v[held:] == v[held - 1])
    # the plain simulation stops there too: no number past the divergence
    xp, _ = source.simulate(t, 0.1, 0.0, theta, codes, np.zeros_like(t), 1e-3, 1)
    assert np.all(np.isnan(xp[held:])) and np.all(np.isfinite(xp[:held]))
    assert np.nanmax(np.abs(xp)) <= kernels.MAX_ANGLE_RAD


def test_a_call_asking_more_steps_than_the_cap_is_refused_before_integrating(source: Any) -> None:
    t = _decay_t(30.0)
    theta = np.array([0.1, 1e12])  # a made-up start: omega 10^6 rad/s
    n_sub = compiled.substeps(0.01, theta, ("b1", "c1"), 0.1)
    assert n_sub == compiled.MAX_SUBSTEPS
    assert (t.size - 1) * n_sub > kernels.MAX_STEPS
    codes = compiled.term_codes(("b1", "c1"))
    x, v, sx, sv, ok = source.simulate_with_sensitivities(
        t, 0.1, 0.0, theta, codes, np.zeros_like(t), np.zeros((t.size, 0)), 1e-3, n_sub
    )
    assert not ok
    assert np.all(x == 0.0) and np.all(v == 0.0) and not np.any(sx) and not np.any(sv)
    xp, _ = source.simulate(t, 0.1, 0.0, theta, codes, np.zeros_like(t), 1e-3, n_sub)
    assert xp[0] == 0.1 and np.all(np.isnan(xp[1:]))
    assert compiled.substeps(0.01, np.array([np.inf]), ("c1",), 0.1) == compiled.MAX_SUBSTEPS
    assert compiled.substeps(0.01, np.array([np.nan]), ("c1",), 0.1) == compiled.MAX_SUBSTEPS


@pytest.mark.slow
def test_the_kernels_release_the_interpreter_lock(source: Any) -> None:
    """The main thread runs while a worker is inside a long kernel call (it could not if the call held
    the lock: no tick could fall inside it)."""
    t = _decay_t(100.0)
    codes = compiled.term_codes(("b1", "c1"))
    theta = np.array([0.05, 10.0])
    span: list[float] = []

    def work() -> None:
        started = time.perf_counter()
        source.simulate_with_sensitivities(
            t, 0.1, 0.0, theta, codes, np.zeros_like(t), np.zeros((t.size, 0)), 1e-3, 150
        )  # 1.5 million steps
        span.extend([started, time.perf_counter()])

    ticks: list[float] = []
    worker = threading.Thread(target=work)
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    started, ended = span
    quarter = (ended - started) / 4
    inside = [tick for tick in ticks if started + quarter < tick < ended - quarter]
    assert inside, f"no tick of the main thread in the middle of a {ended - started:.2f} s kernel call"


def test_a_module_built_the_old_way_is_never_loaded(monkeypatch: pytest.MonkeyPatch) -> None:
    """How the module is built (the lock released, the host's features) is part of its name, like the
    kernel source: a module built before holding the lock is not picked up."""
    built_now = compiled.native_path()
    monkeypatch.setattr(compiled, "BUILD_SETTINGS", "")
    assert compiled.native_path() != built_now


def _rosenbrock_counted(calls: list[np.ndarray], after: Callable[[int], None] = lambda n: None) -> Any:
    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        calls.append(x.copy())
        after(len(calls))
        f = np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])
        return f, np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])

    return evaluate


def test_a_solve_is_cancelled_at_its_next_evaluation_and_a_spent_budget_starts_none() -> None:
    cancel = threading.Event()
    calls: list[np.ndarray] = []
    evaluate = _rosenbrock_counted(calls, after=lambda n: cancel.set() if n == 3 else None)
    with solve_budget(1e9, cancel) as budget, pytest.raises(FitAbandoned, match="cancelled"):
        levenberg_marquardt(evaluate, np.array([-1.2, 1.0]), xtol=1e-15, ftol=1e-15, max_nfev=10_000)
    assert len(calls) == 3 and budget.abandoned
    calls.clear()
    with solve_budget(0.0) as spent, pytest.raises(FitAbandoned, match="budget of 0 s"):
        levenberg_marquardt(_rosenbrock_counted(calls), np.array([-1.2, 1.0]))
    assert calls == [] and spent.abandoned
    # outside a budget the same solve runs to its own end, and IdentificationError covers an abandoned one
    assert levenberg_marquardt(_rosenbrock_counted(calls), np.array([-1.2, 1.0])).status in (1, 2, 3, 4)
    assert issubclass(FitAbandoned, IdentificationError)


def test_the_solver_stops_on_its_evaluation_cap_when_every_trial_diverges() -> None:
    calls: list[np.ndarray] = []

    def diverging(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        calls.append(x)
        if len(calls) == 1:
            return np.array([1.0, 2.0]), np.eye(2)
        return np.array([np.nan, np.inf]), np.eye(2)  # every trial: a simulation that diverged

    result = levenberg_marquardt(diverging, np.zeros(2), xtol=0.0, ftol=0.0, gtol=0.0, max_nfev=25)
    assert result.status == 0 and result.nfev == 25 == len(calls)
    assert np.all(result.x == 0.0)


def test_a_start_the_model_diverges_from_is_an_identification_error_not_a_crash() -> None:
    t = _decay_t(12.0)
    angle = 0.14 * np.exp(-0.1 * t) * np.cos(np.pi * t)
    run = DecayRun(t=t, angle=angle, rate=np.gradient(angle, t), axis="roll", name="clean")
    with pytest.raises(IdentificationError, match="diverges from its starting point"):
        OutputErrorFit("b1,c1", compute_diagnostics=False).fit([run], start={"b1": 0.1, "c1": 1e9})


@pytest.mark.slow
def test_a_made_up_start_that_runs_away_is_abandoned_at_its_budget() -> None:
    """b1 = 5000 needs 1000 sub-steps per sample: every evaluation takes about half a second."""
    t = _decay_t(12.0)
    angle = 0.14 * np.exp(-0.1 * t) * np.cos(np.pi * t)
    run = DecayRun(t=t, angle=angle, rate=np.gradient(angle, t), axis="roll", name="clean")
    estimator = OutputErrorFit("b1,c1", compute_diagnostics=False)
    with solve_budget(0.5) as budget, pytest.raises(FitAbandoned, match=r"budget of 0\.5 s"):
        estimator.fit([run], start={"b1": 5e3, "c1": 10.0})
    assert budget.abandoned
    assert estimator._n_sub > 500  # the runaway was real: the kernel integrated at that many sub-steps


def _swath_samples(seed: int = 0) -> np.ndarray:
    settings = RecordSettings(port="sim", hull="swath", draft=1.0, angle_deg=8.0, runs=1, sim_seed=seed)
    samples, _trace = RecordDaemon(settings).simulation_scenario().samples()
    return samples


def _wait_for(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        assert time.monotonic() < deadline, f"{what} did not happen within {DEADLINE_S:g} s"
        time.sleep(0.01)


class GyroInMilliradians(OnlineIdentifier):
    """The real identifier given the gyro 1000x too large (mrad/s read as rad/s): its refits run away."""

    def update(self, t: np.ndarray, angle: np.ndarray, rate: np.ndarray | None = None) -> Any:
        return super().update(t, angle, None if rate is None else np.asarray(rate) * GYRO_SCALE)


@pytest.mark.slow
def test_a_live_refit_that_runs_away_is_abandoned_noted_and_the_worker_stops() -> None:
    samples = _swath_samples()
    release = int(np.argmax(samples["t"] >= 10.0))
    decay = samples[release : release + 1500]
    identifier = GyroInMilliradians("ittc-quadratic-restoring")
    live = BackgroundFit(identifier, refit_budget_s=1e-6)  # kept by no refit, on any machine
    try:
        live.submit(decay["t"], decay["roll"], decay["p"])
        _wait_for(lambda: bool(identifier.failures_), "the first refit's end")
        assert "abandoned" in identifier.failures_[0], identifier.failures_
        (note,) = live.take_notes()
        assert "abandoned past its 1e-06 s budget" in note and "cannot follow" in note
        with pytest.raises(IdentificationError, match=r"within 0\.5 s|abandoned"):
            live.finish(timeout_s=0.5)  # the final fit runs away too: given up, and cancelled
        live._thread.join(DEADLINE_S)
        assert not live._thread.is_alive(), "the abandoned worker kept fitting"
    finally:
        live.close()


@pytest.mark.slow
def test_a_runaway_refit_in_the_recorder_is_abandoned_and_the_file_closes_complete(tmp_path: Path) -> None:
    samples = _swath_samples(seed=1)
    identifiers: list[GyroInMilliradians] = []

    def make_identifier(*args: Any, **kwargs: Any) -> GyroInMilliradians:
        identifiers.append(GyroInMilliradians(*args, **kwargs))
        return identifiers[-1]

    hull = load_hull("swath")
    recording = RecordingSink(
        tmp_path, describe_run("roll", 8.0, hull=hull, draft=1.0, sample_rate_hz=100.0), draft=1.0
    )
    # a budget no refit can keep (a microsecond): every refit is abandoned whatever this machine's speed,
    # so the test does not hang on a machine fast enough to finish a runaway refit within a looser one
    sinks = [recording, ViewSink(LiveView("none"))]
    session = DecayPipeline(DetectionSettings(), sinks, fit=LiveFit(make_identifier, refit_budget_s=1e-6))
    outcomes = []
    try:
        for start in range(0, samples.size, 2):  # 20 ms reads at 100 Hz
            outcomes += session.feed(StreamBlock(samples[start : start + 2], b"", 0.0))
            if identifiers and not identifiers[0].failures_:
                active = session.decay
                if active is not None and samples["t"][start] > active.release_t + 8.0:
                    _wait_for(lambda: bool(identifiers[0].failures_), "the runaway refit's abandonment")
            if outcomes:
                break
    finally:
        session.close()
    (outcome,) = outcomes
    assert outcome.path is not None
    with outcome.path.open("rb") as f:
        summary = make_reader(f).get_summary()  # the official reader needs the footer and summary
    assert summary is not None and summary.statistics.message_count > 0
    recorded = read_recording(outcome.path)
    warnings = [e["message"] for e in recorded.events if e["kind"] == "warning"]
    assert any("abandoned past its 1e-06 s budget" in w for w in warnings), warnings
    assert recorded.events[-1]["kind"] == "settled"
    counters = recorded.samples["counter"].astype(np.int64)
    assert np.all(np.diff(counters) % 65536 == 1), "every sample reached the file while refits ran away"
