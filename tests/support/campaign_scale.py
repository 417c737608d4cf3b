"""Campaigns at scale (tests/campaign/test_campaign_dask.py, bench/bench_campaign_scale.py): many synthetic
recordings written cheaply, and a real Dask cluster on this machine, one ``dask scheduler`` and
``dask worker`` processes of the venv's Dask CLI, as a lab starts them on its server.

Every process started here is stopped on exit (terminate, then kill after a bound).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np

from tankdaq.campaign.synthetic import SimulatedTest, simulated_decay, write_simulated_recording
from tankdaq.config.hulls import format_draft, load_hull

#: How long the scheduler and its workers have to come up on a loaded machine.
START_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 10.0


def write_many_decays(
    folder: Path,
    n: int,
    hulls: tuple[str, ...] = ("trimaran", "catamaran", "swath"),
    drafts: tuple[float, ...] = (0.9, 1.0, 1.1),
    repeats: int = 2,
    test: SimulatedTest | None = None,
) -> list[Path]:
    """``n`` MCAP recordings in groups of ``repeats`` (folders repeat1, repeat2, ...) over the hulls,
    drafts and ``n / (len(hulls) len(drafts) repeats)`` nominal angles from 2 to 10 deg. Simulating a
    decay is the costly part (0.4 s), so each hull and draft is simulated from 2, 4, 6 and 8 deg once
    and every recording is the nearest of those with its own sensor noise, labelled with its group's
    nominal angle: a campaign's work, not its physics."""
    per = max(1, n // (len(hulls) * len(drafts) * repeats))
    nominal = [round(float(a), 3) for a in np.linspace(2.0, 10.0, per)] if per > 1 else [6.0]
    test = test or SimulatedTest()
    rng = np.random.default_rng(0)
    written = []
    for hull_name in hulls:
        model = load_hull(hull_name).simulation_model("pitch")
        for draft in drafts:
            coefficients = model.coefficients(draft)
            base = {a: simulated_decay(coefficients, a, test, rng) for a in (2.0, 4.0, 6.0, 8.0)}
            for angle_deg in nominal:
                t, angle, rate = base[min(base, key=lambda a: abs(a - angle_deg))]
                for repeat in range(1, repeats + 1):
                    stem = f"{hull_name}_{format_draft(draft)}_pitch_{angle_deg:g}deg_run01.mcap"
                    path = folder / f"repeat{repeat}" / stem
                    path.parent.mkdir(parents=True, exist_ok=True)
                    noisy = (
                        angle + rng.normal(0.0, test.angle_noise_rad, t.size),
                        rate + rng.normal(0.0, test.rate_noise_rad_s, t.size),
                    )
                    labels = (hull_name, "pitch", draft, angle_deg)
                    written.append(write_simulated_recording(path, labels, t, *noisy, test))
    return written


def _dask(*arguments: str) -> list[str]:
    """The venv's ``dask`` command (the module form: the console script may be absent)."""
    return [sys.executable, "-m", f"distributed.cli.dask_{arguments[0]}", *arguments[1:]]


@contextmanager
def _process(command: list[str], log: Path) -> Iterator[subprocess.Popen[bytes]]:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    with log.open("wb") as out:
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, env=env)
    try:
        yield process
    finally:
        process.terminate()
        try:
            process.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@contextmanager
def dask_cluster(workers: int, folder: Path) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """(scheduler address, [scheduler, worker...] processes) of a cluster of ``workers`` single-threaded
    worker processes (no nanny: one process each), once every worker has joined."""
    from distributed import Client

    file = folder / "scheduler.json"
    with ExitStack() as stack:
        scheduler = stack.enter_context(
            _process(
                _dask("scheduler", "--port", "0", "--no-dashboard", "--scheduler-file", str(file)),
                folder / "scheduler.log",
            )
        )
        address = _wait_for_address(file, scheduler)
        processes = [scheduler]
        for i in range(workers):
            command = _dask("worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard")
            processes.append(stack.enter_context(_process(command, folder / f"worker{i}.log")))
        with Client(address, timeout=START_TIMEOUT_S) as client:
            client.wait_for_workers(workers, timeout=START_TIMEOUT_S)
        yield address, processes


def _wait_for_address(file: Path, scheduler: subprocess.Popen[bytes]) -> str:
    """The scheduler's address once it has written its file (bounded; it must still be running)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and scheduler.poll() is None:
        try:
            return str(json.loads(file.read_text())["address"])
        except (OSError, ValueError, KeyError):
            time.sleep(0.05)  # polling the scheduler's file, a real condition with a bound
    raise RuntimeError(f"dask scheduler did not start (exit {scheduler.poll()}); see {file.parent}")
