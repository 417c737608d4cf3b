"""Clipped samples in a fit: left out (residuals masked) against kept, over simulated clipped decays.

Run: .venv/bin/python bench/bench_clipping.py [seeds]
Each seed: the default hull released at 8 deg with a gyro range of 16 deg/s (the ``clipped-decay``
scripted fault: the first swings clip), fitted from the release with the true model's terms by the
output-error engine, once with the flagged samples excluded and once with them kept. Prints the
median and worst relative error of c3 and of B_eq at 5 deg against the truth, and the rate residual.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from benchjson import write_result
from tankdaq.config.hulls import hull_scenario
from tankdaq.ident.derived import b_eq
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.scenario import scripted_run
from tankdaq.records import DecayRun
from tankdaq.samples import sample_flags


def one(seed: int) -> dict[str, tuple[float, float, float]]:
    scenario = hull_scenario(runs=1, seed=seed, decay_s=15.0, **scripted_run("clipped-decay", 8.0))
    samples, trace = scenario.samples()
    truth = trace.runs[0].coefficients
    free = samples[trace.runs[0].release_index :]
    excluded = sample_flags(free["status"]).unusable
    terms = tuple(k for k in ("b1", "b2", "b3", "c1", "c2", "c3") if truth.get(k))
    out = {}
    for label, mask in (("excluded", excluded), ("kept", None)):
        run = DecayRun(free["t"], free["roll"], free["p"], excluded=mask)
        fit = OutputErrorFit(terms).fit([run])
        c3 = abs(fit.coefficients_["c3"] / truth["c3"] - 1)
        beq = abs(b_eq(fit.coefficients_, math.radians(5)) / b_eq(truth, math.radians(5)) - 1)
        out[label] = (c3, beq, math.degrees(fit.sigmas_[0]["rate"]))
    out["clipped"] = (float(excluded.sum()), 0.0, 0.0)
    return out


def main(seeds: int) -> None:
    rows = [one(seed) for seed in range(seeds)]
    clipped = [r["clipped"][0] for r in rows]
    print(f"{seeds} clipped decays, {np.median(clipped):.0f} flagged samples (median) of about 1500")
    print(
        "clipped samples | c3 error median / worst | B_eq(5 deg) error median / worst | rate residual deg/s"
    )
    figures: dict[str, object] = {"flagged_samples_median": float(np.median(clipped))}
    for label in ("excluded", "kept"):
        c3, beq, rate = (np.array([r[label][k] for r in rows]) for k in range(3))
        print(
            f"{label:8s} | {np.median(c3):6.1%} / {c3.max():6.1%} | {np.median(beq):6.1%} / {beq.max():6.1%} "
            f"| {np.median(rate):.3f}"
        )
        figures[label] = {
            "c3_rel_error_median": np.median(c3),
            "c3_rel_error_worst": c3.max(),
            "b_eq_5deg_rel_error_median": np.median(beq),
            "b_eq_5deg_rel_error_worst": beq.max(),
            "rate_residual_deg_s_median": np.median(rate),
        }
    write_result(
        "clipping",
        "clipped decays (8 deg, gyro range 16 deg/s) fitted with the flagged samples left out and kept: "
        "errors of c3 and B_eq(5 deg) against the truth",
        counts={"seeds": seeds},
        figures=figures,
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
