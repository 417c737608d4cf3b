"""The model chosen by data (issue 19): what ``identify``'s default costs, and the live family's refits.

For a simulated SWATH decay (seed 001's cubic damping, 10 deg, 5 s and 15 s at 100 Hz, MTi-G-like noise)
and KVLCC2 run 21338 (19 464 samples, rad): the wall time of ``choose_model`` (ten output-error fits:
each family model on the whole record and on its first 60 %), against one fit of the old default
b1,b2,c1,c3, and which model it chooses; then the live identifier with ``terms="auto"`` on the 15 s
SWATH decay fed in 20-sample blocks: its refits, the model sizes it went through and its longest refit.

Run: .venv/bin/python bench/bench_model_choice.py   (about half a minute)
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np

from benchjson import write_result
from tankdaq.ident.free_decay import cut_free_decays
from tankdaq.ident.inputs import read_decays
from tankdaq.ident.model_choice import choose_model
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.live.identifier import OnlineIdentifier
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

SWATH_T = {"b1": 0.2947, "b2": 0.013215, "b3": 12.0454, "c1": 14.2185, "c2": 0.027792, "c3": 69.457}
KVLCC2 = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)


def swath(duration_s: float) -> DecayRun:
    t = np.arange(0.0, duration_s, 0.01)
    angle, rate = simulate_decay(SWATH_T, t, math.radians(10.0))
    rng = np.random.default_rng(0)
    return DecayRun(t, angle + rng.normal(0, 3e-4, t.size), rate + rng.normal(0, 2e-3, t.size))


def timed_choice(name: str, runs: list[DecayRun]) -> dict[str, float]:
    started = time.perf_counter()
    OutputErrorFit("b1,b2,c1,c3").fit(runs)
    one = time.perf_counter() - started
    started = time.perf_counter()
    choice = choose_model(runs)
    wall = time.perf_counter() - started
    print(f"{name}: choose_model {wall:.2f} s (one b1,b2,c1,c3 fit {one:.2f} s); {choice.reason}")
    return {"choose_model_s": wall, "one_fit_s": one, "choose_over_one_fit": wall / one}


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.2f}")
    OutputErrorFit("b1,c1").fit([swath(5.0)])  # kernels loaded before any timing
    figures: dict[str, object] = {}
    for duration in (5.0, 15.0):
        figures[f"swath_{duration:g}s"] = timed_choice(f"SWATH {duration:g} s", [swath(duration)])
    if KVLCC2.is_file():
        runs = cut_free_decays(read_decays(KVLCC2, None, "time", "phi", None, "rad"), None, None)
        figures["kvlcc2_21338"] = timed_choice("KVLCC2 21338", runs)
    run = swath(15.0)
    live = OnlineIdentifier("auto")
    slowest = 0.0
    for start in range(0, run.t.size, 20):
        window = slice(start, start + 20)
        began = time.perf_counter()
        live.update(run.t[window], run.angle[window], run.rate[window])
        slowest = max(slowest, time.perf_counter() - began)
    began = time.perf_counter()
    final = live.finish()
    final_s = time.perf_counter() - began
    sizes = [len(r.coefficients) for r in live.results_]
    print(
        f"live auto: {len(live.results_)} fits, model sizes {sizes}, longest refit {slowest:.3f} s, "
        f"final {','.join(final.coefficients)} in {final_s:.3f} s"
    )
    figures["live_auto_15s"] = {
        "fits": len(live.results_),
        "longest_refit_s": slowest,
        "final_fit_s": final_s,
    }
    write_result(
        "model_choice",
        "choose_model (ten output-error fits) against one b1,b2,c1,c3 fit on SWATH decays and KVLCC2 run "
        "21338; "
        "the live identifier with terms=auto on a 15 s decay fed in 20-sample blocks",
        counts={"kvlcc2": KVLCC2.is_file(), "block_samples": 20},
        figures=figures,
    )


if __name__ == "__main__":
    main()
