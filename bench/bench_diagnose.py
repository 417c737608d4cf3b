"""Time of the whole discrepancy workflow on three decays of 15 s at 100 Hz (target: <= 5 s on one core).

Run: .venv/bin/python bench/bench_diagnose.py
The first call compiles (or loads from cache) the numba kernel; it is reported apart.
"""

from __future__ import annotations

import statistics
import time

from benchjson import write_result
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.diagnose.workflow import Diagnoser

CASES: tuple[tuple[str, ...], ...] = (
    (),
    ("damping.quadratic",),
    ("restoring.cubic",),
    ("sensor.lag",),
    ("coupling.heave",),
    ("disturbance.late",),
    ("damping.quadratic", "sensor.offset"),
)
REPEATS = 5


def time_case(effects: tuple[str, ...]) -> tuple[float, int, int]:
    """Median wall time over seeds, the refits it took, and the steps accepted."""
    times, refits, steps = [], [], []
    for seed in range(REPEATS):
        runs = make_decay_set(effects, seed=seed, duration_s=15.0, rate_hz=100.0).runs
        labels: list[str] = []  # one per refit
        started = time.perf_counter()
        diagnoser = Diagnoser(progress=labels.append).fit(runs)
        times.append(time.perf_counter() - started)
        refits.append(len(labels))
        steps.append(len(diagnoser.steps_))
    return statistics.median(times), round(statistics.median(refits)), round(statistics.median(steps))


def main() -> None:
    runs = make_decay_set((), seed=0).runs
    started = time.perf_counter()
    Diagnoser().fit(runs)
    first = time.perf_counter() - started
    print(f"first call (kernel compile or cache load included): {first:.2f} s")
    figures: dict[str, object] = {"first_call_s": first}
    print(f"{'hidden effects':40s} {'median s':>9s} {'refits':>7s} {'ms/refit':>9s} {'steps':>6s}")
    worst = 0.0
    for effects in CASES:
        seconds, refits, steps = time_case(effects)
        worst = max(worst, seconds)
        label = " + ".join(effects) or "none (negative control)"
        print(f"{label:40s} {seconds:9.2f} {refits:7d} {1000 * seconds / refits:9.1f} {steps:6d}")
        figures[label] = {"median_s": seconds, "refits": refits, "steps": steps}
    print(f"slowest case: {worst:.2f} s (target <= 5 s)")
    figures["slowest_case_s"] = worst
    write_result(
        "diagnose",
        "wall time of the discrepancy workflow on three decays of 15 s at 100 Hz per hidden-effect case "
        "(median over seeds; target <= 5 s on one core)",
        counts={"seeds": REPEATS, "cases": len(CASES)},
        figures=figures,
    )


if __name__ == "__main__":
    main()
