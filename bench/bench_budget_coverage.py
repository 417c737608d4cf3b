"""Coverage of the uncertainty budget (issue 38, "Coverage"): over simulated campaigns of 3 repeats with
known truth and realistic noise, how often U (k = 2) of the natural period and of B_eq/I at 5 deg covers
the truth (the budget is right when 90-99 %). The campaigns are ``tests/support/budget_coverage.py``'s (the
test runs a few of the same).

Run: .venv/bin/python bench/bench_budget_coverage.py [--campaigns 200]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchjson import write_result

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support.budget_coverage import INITIAL_DEG, REPEATS, TEST, campaign, coverage, truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=200)
    args = parser.parse_args()
    coefficients = truth()
    outcomes = [campaign(seed, coefficients) for seed in range(args.campaigns)]
    found = coverage(outcomes)
    exact = coverage([campaign(seed, coefficients, device_error=False) for seed in range(args.campaigns)])
    write_result(
        "budget_coverage",
        "share of simulated campaigns whose expanded uncertainty U (k=2) covers the truth",
        counts={
            "campaigns": args.campaigns,
            "repeats_per_campaign": REPEATS,
            "condition": f"catamaran roll at T from {INITIAL_DEG:g} deg, {TEST.duration_s:g} s at "
            f"{TEST.rate_hz:g} Hz",
            "noise": "white angle/rate noise (SimulatedTest), 0.01 deg quantisation, angle bias, "
            "per-campaign angle scale and clock errors at the MTi-G-710 profile's figures",
            "target_covered": [0.90, 0.99],
        },
        figures={"coverage": found, "coverage_with_an_exact_device": exact},
        note="the first figures are the issue's (device errors drawn at the profile's figures, as the "
        "budget's Type B assumes); with an exact device the Type B rows cover an error that is not there",
    )
    for key, figures in found.items():
        print(
            f"{key}: U covers the truth in {figures['covered']:.1%} of {args.campaigns} campaigns, "
            f"RMS error/u_c {figures['rms_error_over_u']:.2f} (an exact device: {exact[key]['covered']:.1%})"
        )


if __name__ == "__main__":
    main()
