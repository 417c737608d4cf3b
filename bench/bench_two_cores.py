"""Are this machine's two cores two? The CPU time of the same work in one process alone, then in two at once.

Where two processes at once each spend more CPU than one alone (shared execution units, a throttled
host), no pool of two can be twice as fast as one process; where they spend the same, a campaign's
``--jobs 2`` shortfall against 2x is its own overhead (bench_campaign_scale.py).

Run: .venv/bin/python bench/bench_two_cores.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import time
from multiprocessing.queues import Queue

import numpy as np

from benchjson import write_result

#: Rounds of the work: a numpy sort and a pure-Python loop, about 1 s of CPU in all.
ROUNDS = 300


def work(results: Queue) -> None:
    """About a second of mixed numpy and interpreter work; puts (CPU s, wall s)."""
    cpu0, wall0 = time.process_time(), time.perf_counter()
    values = np.random.default_rng(0).standard_normal(200_000)
    total = 0.0
    for i in range(ROUNDS):
        total += float(np.sort(values)[i])
        total += sum(j * j for j in range(20_000)) * 0.0
    results.put((time.process_time() - cpu0, time.perf_counter() - wall0))


def run(processes: int) -> list[tuple[float, float]]:
    """(CPU s, wall s) of each of ``processes`` forked at once."""
    context = multiprocessing.get_context("fork")
    results: Queue = context.Queue()
    children = [context.Process(target=work, args=(results,)) for _ in range(processes)]
    for child in children:
        child.start()
    measured = [results.get() for _ in children]
    for child in children:
        child.join()
    return measured


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average {os.getloadavg()[0]:.1f}")
    ratios = []
    for _ in range(args.repeats):
        (alone,) = run(1)
        both = run(2)
        cpu_ratio = max(cpu for cpu, _ in both) / alone[0]
        print(
            f"alone {alone[0]:.3f} s CPU; two at once {both[0][0]:.3f} and {both[1][0]:.3f} s CPU "
            f"(the slower {cpu_ratio:.2f}x alone)"
        )
        ratios.append(cpu_ratio)
    write_result(
        "two_cores",
        "CPU time of about a second of numpy and interpreter work in one process alone, then in two at once",
        counts={"repeats": args.repeats},
        figures={"slower_of_two_cpu_over_alone_median": float(np.median(ratios))},
        ratios={"slower_of_two_cpu_over_alone_median": float(np.median(ratios))},
        baseline="the same work in one process alone, same run",
    )


if __name__ == "__main__":
    main()
