"""How long finding one decay read twice takes: ``ident.repeats.repeated_decays`` over N decays.

The hard case: N decays of one condition, alike in all but their noise (15 s at 100 Hz, noise 1e-4 rad on
a 0.15 rad decay), so many samples of one agree with another's by chance and must be ruled out; and the
same N with a tenth of them copies cut at another point (all found).

Run: .venv/bin/python bench/bench_repeats.py [--sizes 36,200,1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchjson import write_result
from tankdaq.ident.repeats import repeated_decays
from tankdaq.records import DecayRun


def alike(count: int, seed: int = 0) -> list[DecayRun]:
    """``count`` decays of one condition differing only in their noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(1500) / 100.0
    runs = []
    for i in range(count):
        angle = 0.15 * np.exp(-0.1 * t) * np.cos(3.0 * t) + rng.normal(0.0, 1e-4, t.size)
        runs.append(DecayRun(t=t.copy(), angle=angle, rate=np.gradient(angle, t), name=f"run{i}"))
    return runs


def with_cut_copies(runs: list[DecayRun]) -> list[DecayRun]:
    """``runs`` and, for every tenth one, a copy of its samples 200 to 1200."""
    cut = [
        DecayRun(t=run.t[200:1200].copy(), angle=run.angle[200:1200].copy(), rate=run.rate[200:1200].copy(),
                 name=f"{run.name}-cut")
        for run in runs[::10]
    ]  # fmt: skip
    return runs + cut


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="36,200,1000")
    args = parser.parse_args()
    print("| N | decays | copies found | CPU s |")
    print("|---:|---|---:|---:|")
    figures: dict[str, dict[str, float]] = {}
    for size in (int(n) for n in args.sizes.split(",")):
        for label, runs in (("alike", alike(size)), ("alike + cut copies", with_cut_copies(alike(size)))):
            start = time.process_time()
            found = repeated_decays(runs)
            cpu = time.process_time() - start
            print(f"| {size} | {label} | {len(found)} | {cpu:.2f} |")
            figures[f"n{size} {label}"] = {"copies_found": len(found), "cpu_s": cpu}
    write_result(
        "repeats",
        "finding one decay read twice among N alike decays (15 s at 100 Hz), with and without cut copies",
        counts={"sizes": args.sizes},
        figures=figures,
    )


if __name__ == "__main__":
    main()
