"""The free-decay cut (issue 10): what fitting past the end of a free decay does, and what the cut costs.

Generated records (x'' + 0.3 x' + 0.4|x'|x' + 14 x + 20 x^3 = f(t), 8 deg from rest, 100 Hz, MTi-G-like
noise): a carriage stop (a 2 s half-sine heel moment of 0.15 rad/s² from 12 s, speed channel 1.2 -> 0 m/s)
and a second push (0.4 s, 1.5 rad/s² at 9.1 s). For each: where the cut falls against the truth, R² and
coefficients fitted over the whole record and over the cut one against the clean record's fit. Then the
cost of the cut on KVLCC2 run 21338 (19 464 samples) against one output-error fit of it.

Run: .venv/bin/python bench/bench_free_decay.py   (about a minute)
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from benchjson import write_result
from tankdaq.ident.free_decay import cut_free_decay, find_free_end
from tankdaq.ident.inputs import read_decays
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

TRUTH = {"b1": 0.3, "b2": 0.4, "c1": 14.0, "c3": 20.0}
PERIOD_S = 2 * math.pi / math.sqrt(TRUTH["c1"])
KVLCC2 = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)


def record(start_s: float, length_s: float, peak: float, speed: bool) -> DecayRun:
    t = np.arange(0.0, 30.0, 0.01)

    def pulse(tt: float) -> float:
        return (
            peak * math.sin(math.pi * (tt - start_s) / length_s)
            if start_s <= tt <= start_s + length_s
            else 0.0
        )

    angle, rate = simulate_decay(TRUTH, t, math.radians(8.0), rtol=1e-9, atol=1e-11, forcing=pulse)
    rng = np.random.default_rng(0)
    channels = {"speed_m_s": np.clip(1.2 * (1 - (t - start_s) / length_s), 0, 1.2)} if speed else {}
    return DecayRun(
        t, angle + rng.normal(0, 3e-4, t.size), rate + rng.normal(0, 2e-3, t.size), channels=channels
    )


def main() -> None:
    terms = tuple(TRUTH)
    clean = OutputErrorFit(terms).fit([record(0.0, 1.0, 0.0, False)])
    print(
        f"clean record: R² {clean.r2_angle_:.5f}; "
        + ", ".join(f"{k} {v:.4g}" for k, v in clean.coefficients_.items())
    )
    cases = {
        "carriage stop, speed channel": (12.0, record(12.0, 2.0, 0.15, True)),
        "carriage stop, roll only": (12.0, record(12.0, 2.0, 0.15, False)),
        "second push": (9.1, record(9.1, 0.4, 1.5, False)),
    }
    print("| record | cut at (truth) | kind | R² whole | R² cut | max coefficient shift whole | cut |")
    figures: dict[str, object] = {"clean_r2_angle": clean.r2_angle_}
    for label, (truth_s, run) in cases.items():
        end = find_free_end(run)
        whole = OutputErrorFit(terms).fit([run])
        cut = OutputErrorFit(terms).fit([cut_free_decay(run)])

        def shift(fit: OutputErrorFit) -> str:
            worst = max(TRUTH, key=lambda k: abs(fit.coefficients_[k] / clean.coefficients_[k] - 1))
            return f"{worst} {100 * (fit.coefficients_[worst] / clean.coefficients_[worst] - 1):+.1f} %"

        print(
            f"| {label} | {end.t_s:.2f} s ({truth_s:g} s, period {PERIOD_S:.2f} s) | {end.kind} | "
            f"{whole.r2_angle_:.4f} | {cut.r2_angle_:.5f} | {shift(whole)} | {shift(cut)} |"
        )
        figures[label] = {
            "cut_at_s": end.t_s,
            "truth_s": truth_s,
            "r2_whole": whole.r2_angle_,
            "r2_cut": cut.r2_angle_,
        }
    if KVLCC2.is_file():
        figures["kvlcc2_21338"] = kvlcc2_cost(terms)
    else:
        print(f"KVLCC2 not found at {KVLCC2}: cost figures skipped")
    write_result(
        "free_decay",
        "the free-decay cut on generated records (a carriage stop, a second push): where it falls, R² over "
        "the whole record and the cut one; its cost on KVLCC2 run 21338 against one output-error fit",
        counts={"cases": 3, "kvlcc2": KVLCC2.is_file()},
        figures=figures,
    )


def kvlcc2_cost(terms: tuple[str, ...]) -> dict[str, float]:
    """The cut of KVLCC2 run 21338 (mean of 10) against one output-error fit of it."""
    (kvlcc2,) = read_decays(KVLCC2, time_col="time", angle_col="phi", rate_col=None, angle_unit="rad")
    start = time.perf_counter()
    for _ in range(10):
        end = find_free_end(kvlcc2)
    cut_s = (time.perf_counter() - start) / 10
    start = time.perf_counter()
    OutputErrorFit(terms).fit([kvlcc2])
    fit_s = time.perf_counter() - start
    print(
        f"KVLCC2 21338 ({kvlcc2.t.size} samples): cut {1e3 * cut_s:.1f} ms ({end.kind}), "
        f"one OE fit {fit_s:.2f} s, ratio {cut_s / fit_s:.3f}"
    )
    return {"samples": kvlcc2.t.size, "cut_ms": 1e3 * cut_s, "oe_fit_s": fit_s, "cut_over_fit": cut_s / fit_s}


if __name__ == "__main__":
    main()
