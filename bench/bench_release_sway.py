"""Release instant from a swaying hold: error and interval coverage against the truth; the detector's speed.

Run: .venv/bin/python bench/bench_release_sway.py [--releases 200] [--baseline main]
Per rate (100, 200, 400 Hz), ``--releases`` simulated hand releases of the swath roll model from a swaying
hold (``Handling.swaying()``: 0.15 deg at 0.9 Hz plus 0.05 deg at 2.3 Hz, random phases, so the rate at
release is not zero) and as many from the still hold (``Handling()``), with MTi-G noise. The error is
``release_t`` minus the true instant (SampleTimeFine ticks of the release / 10 kHz); the interval is the
event's 95 % one (``release_t`` ± ``release_u95_s``). The same samples go through the detector of
``--baseline`` (a git revision, its ``src/`` extracted to a temporary folder; ``--baseline none`` skips
it) in a child process, so the old estimator's errors and speed are measured in the same run: offline
(one array) and live (fed in 0.1 s blocks, one detector per scenario). Writes
bench/results/release_sway.json.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchjson import write_result

RATES_HZ = (100, 200, 400)
HOLDS = ("swaying", "still")
RUNS_PER_SCENARIO = 25
DECAY_S = 25.0
ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results" / "release_sway.json"


def scenarios(hold: str, rate_hz: int, releases: int) -> list[tuple[np.ndarray, list[float], list[int]]]:
    """(samples, true release instants (s), true first free samples) of each scenario."""
    from tankdaq.config.hulls import hull_scenario
    from tankdaq.physics.scenario import Handling
    from tankdaq.physics.truth import TICKS_PER_S

    handling = Handling.swaying() if hold == "swaying" else Handling()
    made = []
    for seed in range(math.ceil(releases / RUNS_PER_SCENARIO)):
        runs = min(RUNS_PER_SCENARIO, releases - seed * RUNS_PER_SCENARIO)
        scenario = hull_scenario(
            runs=runs, seed=9000 + seed, rate_hz=rate_hz, decay_s=DECAY_S, handling=handling
        )
        samples, trace = scenario.samples()
        truth = [r.release_ticks / TICKS_PER_S for r in trace.runs if r.release_ticks is not None]
        index = [int(r.release_index) for r in trace.runs if r.release_index is not None]
        made.append((samples, truth, index))
    return made


def detect(folder: Path) -> dict[str, object]:
    """Child: the detector of the tree on PYTHONPATH over every scenario saved in ``folder``."""
    from tankdaq.acquire.release import ReleaseDetector

    out: dict[str, object] = {}
    for path in sorted(folder.glob("*.npy")):
        samples = np.load(path)
        start = time.perf_counter()
        offline = [e for e in ReleaseDetector(axis="roll").fit(samples).events_ if e.kind == "released"]
        offline_s = time.perf_counter() - start
        block = round(float(1.0 / np.median(np.diff(samples["t"][:100]))) / 10)
        live = ReleaseDetector(axis="roll", keep_events=False)
        start = time.perf_counter()
        for first in range(0, samples.size, block):
            live.feed(samples[first : first + block])
        live_s = time.perf_counter() - start
        out[path.stem] = {
            "offline_s": offline_s,
            "live_s": live_s,
            "samples": int(samples.size),
            "events": [
                {
                    "index": e.index,
                    "t": e.release_t,
                    "u95": getattr(e, "release_u95_s", math.nan),
                    "se": e.release_se_s,
                }
                for e in offline
            ],
        }
    return out


def run_tree(folder: Path, src: Path) -> dict[str, object]:
    env = {**os.environ, "PYTHONPATH": str(src), "TANKDAQ_CONFIG_DIR": str(ROOT / "configs")}
    child = [sys.executable, __file__, "--child", str(folder)]
    done = subprocess.run(child, env=env, check=True, capture_output=True, text=True)
    return json.loads(done.stdout)


def figures(found: dict[str, object], truths: dict[str, tuple[list[float], list[int]]]) -> dict[str, object]:
    """Errors and coverage of one tree over the scenarios of one hold and rate."""
    errors, covered, widths, se_covered, missed = [], [], [], [], 0
    offline_s = live_s = 0.0
    samples = 0
    for name, (truth, index) in truths.items():
        got = found[name]
        offline_s += got["offline_s"]
        live_s += got["live_s"]
        samples += got["samples"]
        for true_s, true_index in zip(truth, index, strict=True):
            near = [e for e in got["events"] if abs(e["index"] - true_index) < 50]
            if not near:
                missed += 1
                continue
            e = near[0]
            errors.append(e["t"] - true_s)
            se_covered.append(abs(e["t"] - true_s) <= 1.96 * e["se"])
            if e["u95"] is not None and math.isfinite(e["u95"]):
                covered.append(abs(e["t"] - true_s) <= e["u95"])
                widths.append(2 * e["u95"])
    err_ms = 1e3 * np.array(errors)
    return {
        "releases": len(errors),
        "missed": missed,
        "bias_ms": float(err_ms.mean()),
        "sd_ms": float(err_ms.std(ddof=1)),
        "min_ms": float(err_ms.min()),
        "max_ms": float(err_ms.max()),
        "p95_abs_ms": float(np.percentile(np.abs(err_ms), 95)),
        "within_10ms": float(np.mean(np.abs(err_ms) <= 10.0)),
        "within_0_6ms": float(np.mean(np.abs(err_ms) <= 0.6)),
        "interval_covers": float(np.mean(covered)) if covered else None,
        "median_interval_ms": float(1e3 * np.median(widths)) if widths else None,
        "within_1_96_se": float(np.mean(se_covered)),
        "offline_us_per_sample": 1e6 * offline_s / samples,
        "live_us_per_sample": 1e6 * live_s / samples,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--releases", type=int, default=200)
    parser.add_argument("--baseline", default="main", help="git revision of the old estimator, or none")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(detect(Path(args.child))))
        return
    cases: dict[str, dict[str, dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"this tree": ROOT / "src"}
        if args.baseline != "none":
            base = Path(tmp) / "baseline"
            base.mkdir()
            archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline, "src"], check=True,
                                     capture_output=True).stdout  # fmt: skip
            subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
            trees = {f"baseline {args.baseline}": base / "src", **trees}
        for hold, rate in itertools.product(HOLDS, RATES_HZ):
            folder = Path(tmp) / f"{hold}_{rate}"
            folder.mkdir()
            truths = {}
            for number, (samples, truth, index) in enumerate(scenarios(hold, rate, args.releases)):
                np.save(folder / f"s{number:03d}.npy", samples)
                truths[f"s{number:03d}"] = (truth, index)
            # the baseline on the swaying hold only: its errors there, both trees' speed on the same samples
            chosen = trees if hold == "swaying" else {"this tree": trees["this tree"]}
            case = {name: figures(run_tree(folder, src), truths) for name, src in chosen.items()}
            cases[f"{hold} {rate} Hz"] = case
            write_result(  # each case as it is done: a long run
                "release_sway",
                "release instant from a swaying and a still hold: error against the truth, 95 % interval "
                "coverage, detector speed (offline and live in 0.1 s blocks), this tree and the baseline on "
                "the same samples",
                counts={"releases_per_case": args.releases},
                figures={"cases": cases},
                baseline=None if args.baseline == "none" else f"the detector of git revision {args.baseline}",
            )
            for name, f in case.items():
                cover = "n/a" if f["interval_covers"] is None else f"{f['interval_covers']:.1%}"
                print(
                    f"{hold:8s} {rate:3d} Hz {name:15s} n={f['releases']} missed={f['missed']} "
                    f"bias {f['bias_ms']:+.2f} ms sd {f['sd_ms']:.2f} ms "
                    f"range {f['min_ms']:+.1f}..{f['max_ms']:+.1f} "
                    f"ms; within 10 ms {f['within_10ms']:.1%}, p95|err| {f['p95_abs_ms']:.2f} ms; "
                    f"95 % interval covers {cover} (1.96 se: {f['within_1_96_se']:.1%}); "
                    f"offline {f['offline_us_per_sample']:.2f} us/sample, "
                    f"live {f['live_us_per_sample']:.2f} us/sample",
                    flush=True,
                )


if __name__ == "__main__":
    main()
