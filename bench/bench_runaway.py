"""A runaway fit and the recorder (issue 19): what a runaway costs, and how fast a signal is heard.

1. The runaway itself: the live model fitted to the simulated swath decay whose gyro is read 1000x
   too large (mrad/s taken for rad/s; ``tests/support/runaway_recorder.py``), cold start, without a budget
   (stopped at ``--cap`` seconds) and with the live refit budget; and the longest single kernel call
   the step cap allows (``kernels.MAX_STEPS`` steps with 4 terms' sensitivities).
2. The main thread's longest pause (a bare 20 ms loop) while that runaway fit runs on a worker thread:
   the kernels release the interpreter lock.
3. Ctrl-C heard while a live refit runs away: ``tests/support/runaway_recorder.py`` (the real daemon on the
   simulated MTi-G) is sent SIGINT at its first ``refit started``; "heard" is when the daemon's loop
   says ``stopping`` (CLOCK_MONOTONIC, shared by the processes), "exit" when the process has ended.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from benchjson import write_result

REPO = Path(__file__).resolve().parents[1]
RUNAWAY = REPO / "tests" / "support" / "runaway_recorder.py"


def runaway_run() -> object:
    """10 s of the decay after its release, the gyro 1000x (what the recorder's first refit sees)."""
    from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
    from tankdaq.records import DecayRun

    settings = RecordSettings(port="sim", hull="swath", draft=1.0, angle_deg=8.0, runs=1)
    samples, trace = RecordDaemon(settings).simulation_scenario().samples()
    release = trace.runs[0].release_index
    decay = samples[release : release + 1000]
    return DecayRun(t=decay["t"], angle=decay["roll"], rate=decay["p"] * 1000.0, axis="roll", name="x")


def fit_seconds(budget_s: float) -> tuple[float, str]:
    from tankdaq.ident.least_squares import solve_budget
    from tankdaq.ident.output_error import OutputErrorFit

    run = runaway_run()
    started = time.perf_counter()
    try:
        with solve_budget(budget_s):
            OutputErrorFit("ittc-quadratic-restoring", compute_diagnostics=False).fit([run])  # type: ignore[list-item]
        how = "finished"
    except Exception as exc:  # the abandoned fit
        how = type(exc).__name__
    return time.perf_counter() - started, how


def longest_kernel_call_s() -> float:
    from tankdaq.ident import compiled, kernels

    codes = compiled.term_codes(("b1", "b2", "c1", "c3"))
    n_sub = 1000
    t = np.arange(kernels.MAX_STEPS // n_sub + 1) * 0.01
    started = time.perf_counter()
    compiled.simulate_with_sensitivities(
        t, 0.1, 0.0, np.array([0.05, 0.0, 10.0, 0.0]), codes, 0 * t, np.zeros((t.size, 0)), 1e-3, n_sub
    )
    return time.perf_counter() - started


def loop_pause_beside_the_runaway(seconds: float) -> tuple[float, float]:
    """(longest, median) pass of a bare 20 ms loop while the runaway fit runs on a thread."""
    worker = threading.Thread(target=fit_seconds, args=(seconds,), daemon=True)
    worker.start()
    passes, last = [], time.perf_counter()
    while worker.is_alive():
        time.sleep(0.02)
        now = time.perf_counter()
        passes.append(now - last)
        last = now
    return max(passes), statistics.median(passes)


def signal_latency(out: Path) -> tuple[float, float, str]:
    proc = subprocess.Popen(
        [sys.executable, str(RUNAWAY), str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    while "refit started" not in proc.stdout.readline():
        if proc.poll() is not None:
            raise RuntimeError(proc.stderr.read() if proc.stderr else "the recorder ended")
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    rest, _ = proc.communicate(timeout=120)
    exited = time.monotonic() - sent
    heard = re.search(r"heard (\S+) refit running (\w+)", rest)
    assert heard is not None, rest
    return float(heard.group(1)) - sent, exited, f"refit running {heard.group(2)}, exit {proc.returncode}"


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cap", type=float, default=120.0, help="stop the unbudgeted fit here (s)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    from tankdaq.ident import compiled
    from tankdaq.live.preparation import prepare_kernels
    from tankdaq.live.worker import REFIT_BUDGET_S

    prepare_kernels()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}, Python {platform.python_version()}, "
          f"native kernels {compiled.ahead_of_time()}")  # fmt: skip
    unbudgeted, how = fit_seconds(args.cap)
    print(f"runaway fit without a budget: {unbudgeted:.1f} s ({how}; stopped at --cap {args.cap:g} s)")
    budgeted, how = fit_seconds(REFIT_BUDGET_S)
    print(f"runaway fit with the live budget {REFIT_BUDGET_S:g} s: {budgeted:.2f} s ({how})")
    kernel_s = longest_kernel_call_s()
    print(f"longest kernel call the step cap allows: {kernel_s:.2f} s")
    longest, median = loop_pause_beside_the_runaway(10.0)
    signals = []
    print(f"20 ms loop beside the runaway fit (10 s): longest pass {longest * 1e3:.1f} ms, "
          f"median {median * 1e3:.1f} ms")  # fmt: skip
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as out:
            heard, exited, what = signal_latency(Path(out))
        print(f"SIGINT during a runaway refit: heard after {heard * 1e3:.0f} ms, exited after {exited:.2f} s "
              f"({what})")  # fmt: skip
        signals.append((heard, exited))
    write_result(
        "runaway",
        "a runaway live fit (gyro read 1000x too large): its time without and with the refit budget, the "
        "longest kernel call, a 20 ms loop's pauses beside it, and SIGINT heard during a runaway refit",
        counts={"cap_s": args.cap, "signal_repeats": args.repeats},
        figures={
            "unbudgeted_fit_s": unbudgeted,
            "budgeted_fit_s": budgeted,
            "longest_kernel_call_s": kernel_s,
            "loop_longest_pass_ms": longest * 1e3,
            "loop_median_pass_ms": median * 1e3,
            "sigint_heard_ms_median": 1e3 * statistics.median(h for h, _ in signals),
            "sigint_exit_s_median": statistics.median(e for _, e in signals),
        },
        ratios={"budgeted_over_unbudgeted": budgeted / unbudgeted},
        baseline="the same fit without a budget, same run",
    )


if __name__ == "__main__":
    main()
