"""Release instant: bias and spread of ``release_t`` against the scenario's truth on the device clock.

Run: .venv/bin/python bench/bench_release_bias.py [--releases 200] [--baseline-src DIR]
Per rate (100, 200, 400 Hz), ``--releases`` simulated hand releases of the swath model (``--axis``) with the
scenario's default hand sway, tremor and MTi-G noise; the error is ``release_t`` minus the true instant
(SampleTimeFine ticks of the release / 10 kHz). Printed: mean bias in samples and ms, its std, the 95th
percentile of |error|, the fraction within one sample, and (where the event carries it) how often the
true instant lies within 1.96 reported standard errors. With ``--baseline-src`` (the ``src/`` of
``git archive COMMIT src | tar -x -C /tmp/base``) the same releases are measured with that code too,
in a child process on its PYTHONPATH, in the same run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchjson import write_result

RATES_HZ = (100, 200, 400)
RUNS_PER_SCENARIO = 25
DECAY_S = 25.0
CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def errors_at(rate_hz: int, releases: int, axis: str = "roll") -> dict[str, list[float]]:
    """Errors (s) and reported standard errors (s) of every release found at ``rate_hz``."""
    from tankdaq.acquire.release import ReleaseDetector
    from tankdaq.config.hulls import hull_scenario
    from tankdaq.physics.truth import TICKS_PER_S

    errors, ses, missed = [], [], 0
    for seed in range(math.ceil(releases / RUNS_PER_SCENARIO)):
        runs = min(RUNS_PER_SCENARIO, releases - seed * RUNS_PER_SCENARIO)
        scenario = hull_scenario(axis=axis, runs=runs, seed=9000 + seed, rate_hz=rate_hz, decay_s=DECAY_S)
        samples, trace = scenario.samples()
        found = [e for e in ReleaseDetector(axis=trace.axis).fit(samples).events_ if e.kind == "released"]
        for run in trace.runs:
            near = [e for e in found if abs(e.index - run.release_index) < 50]
            if not near or run.release_ticks is None:
                missed += 1
                continue
            errors.append(near[0].release_t - run.release_ticks / TICKS_PER_S)
            ses.append(float(getattr(near[0], "release_se_s", math.nan)))
    return {"errors_s": errors, "se_s": ses, "missed": [float(missed)]}


def stats(rate_hz: int, measured: dict[str, list[float]]) -> dict[str, float]:
    """Bias, spread and coverage of one rate's release instants, in samples and ms."""
    err = np.array(measured["errors_s"])
    ses = np.array(measured["se_s"])
    samples = err * rate_hz
    covered = np.mean(np.abs(err) <= 1.96 * ses) if np.isfinite(ses).all() and ses.size else math.nan
    return {
        "n": err.size,
        "missed": measured["missed"][0],
        "bias_samples": samples.mean(),
        "bias_ms": 1e3 * err.mean(),
        "std_samples": samples.std(ddof=1),
        "p95_abs_samples": np.percentile(np.abs(samples), 95),
        "within_1_sample": np.mean(np.abs(samples) <= 1),
        "median_se_ms": 1e3 * np.median(ses),
        "within_1_96_se": covered,
    }


def summary(rate_hz: int, s: dict[str, float]) -> str:
    return (
        f"{rate_hz:4d} Hz n={s['n']:3.0f} missed={s['missed']:.0f} "
        f"bias {s['bias_samples']:+.3f} samples ({s['bias_ms']:+.2f} ms) "
        f"std {s['std_samples']:.3f} samples; p95|err| {s['p95_abs_samples']:.2f} samples; "
        f"within 1 sample {s['within_1_sample']:.1%}; "
        f"median se {s['median_se_ms']:.2f} ms, true within 1.96 se {s['within_1_96_se']:.1%}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--releases", type=int, default=200)
    parser.add_argument("--baseline-src", default=None)
    parser.add_argument("--axis", default="roll", help="roll, or pitch (heavily damped: b1 ~ 2)")
    parser.add_argument("--json", action="store_true", help="print the raw errors as JSON (child mode)")
    args = parser.parse_args()
    if args.json:
        print(json.dumps({rate: errors_at(rate, args.releases, args.axis) for rate in RATES_HZ}))
        return
    trees: list[tuple[str, str | None]] = [("this tree", None)]
    if args.baseline_src:
        trees.insert(0, (f"baseline {args.baseline_src}", args.baseline_src))
    figures: dict[str, dict[str, dict[str, float]]] = {}
    for name, src in trees:
        # an archived src/ has no configs folder beside it: both trees read this one's hulls
        env = {**os.environ, "TANKDAQ_CONFIG_DIR": str(CONFIGS)}
        if src:
            env["PYTHONPATH"] = src
        child = [sys.executable, __file__, "--json", "--releases", str(args.releases), "--axis", args.axis]
        done = subprocess.run(child, env=env, check=True, capture_output=True, text=True)
        measured = json.loads(done.stdout)
        print(f"{name}: swath {args.axis}")
        figures[name] = {f"{rate}hz": stats(rate, measured[str(rate)]) for rate in RATES_HZ}
        for rate in RATES_HZ:
            print("  " + summary(rate, figures[name][f"{rate}hz"]))
    write_result(
        "release_bias",
        f"release instant on the device clock: bias and spread of release_t against the truth over simulated "
        f"hand releases of the swath ({args.axis}) per rate",
        counts={"releases_per_rate": args.releases, "axis": args.axis},
        figures=figures,
        baseline=f"--baseline-src {args.baseline_src} (rows 'baseline'), same run"
        if args.baseline_src
        else None,
    )


if __name__ == "__main__":
    main()
