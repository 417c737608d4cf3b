"""Release detection: accuracy against the scenario's truth, confirmation delay, and speed.

Run: .venv/bin/python bench/bench_release.py
Prints, per case, how far the reported first free sample is from the true one (in samples),
how long after the release the detector was sure, and how fast scenario generation and
offline detection run.
"""

from __future__ import annotations

import time

import numpy as np

from benchjson import write_result
from tankdaq.acquire.release import ReleaseDetector
from tankdaq.config.hulls import hull_scenario
from tankdaq.physics.scenario import Handling

CASES = [
    # (axis, rate Hz, angle deg, runs)
    ("roll", 100, 8.0, 60),
    ("roll", 400, 8.0, 40),
    ("roll", 400, 4.0, 40),
    ("pitch", 100, 8.0, 60),
    ("pitch", 400, 8.0, 40),
    ("pitch", 400, 4.0, 40),
]


def accuracy(axis: str, rate_hz: float, angle_deg: float, runs: int) -> dict[str, float]:
    scenario = hull_scenario(axis=axis, rate_hz=rate_hz, angle_deg=angle_deg, runs=runs, seed=101)
    start = time.perf_counter()
    samples, trace = scenario.samples()
    generated = time.perf_counter() - start
    start = time.perf_counter()
    events = ReleaseDetector(axis=axis).fit(samples).events_
    detected = time.perf_counter() - start
    released = [e for e in events if e.kind == "released"]
    errors, delays = [], []
    for run in trace.runs:
        near = [e for e in released if abs(e.index - run.release_index) < 100]
        if near:
            errors.append(near[0].index - run.release_index)
            delays.append((near[0].confirmed_index - near[0].index) / rate_hz)
    errors_arr = np.array(errors)
    within = np.mean(np.abs(errors_arr) <= 1) if errors else 0.0
    histogram = {int(k): int(v) for k, v in zip(*np.unique(errors_arr, return_counts=True), strict=True)}
    print(
        f"{axis:5s} {rate_hz:4.0f} Hz {angle_deg:4.1f} deg: {len(errors)}/{len(trace.runs)} found, "
        f"{len(released) - len(errors)} false; within 1 sample {within:6.1%}; error histogram {histogram}; "
        f"confirmed {np.median(delays):.2f} s after release (median); "
        f"generate {samples.size / generated / 1e6:.2f} M samples/s, "
        f"detect {samples.size / detected / 1e6:.2f} M samples/s"
    )
    return {
        "found": len(errors),
        "runs": len(trace.runs),
        "false": len(released) - len(errors),
        "within_1_sample": float(within),
        "confirmed_after_release_s_median": float(np.median(delays)),
        "detect_m_samples_per_s": samples.size / detected / 1e6,
    }


def handling_hour() -> dict[str, dict[str, float]]:
    """An hour of tilting, holding and putting back (no release): generation and scan speed."""
    figures = {}
    for rate_hz in (100, 400):
        scenario = hull_scenario(runs=110, seed=7, rate_hz=rate_hz, handling=Handling(put_back_fraction=1.0),
                                 release_after_s=12.0, decay_s=21.0)  # fmt: skip
        start = time.perf_counter()
        samples, _ = scenario.samples()
        generated = time.perf_counter() - start
        start = time.perf_counter()
        events = ReleaseDetector().fit(samples).events_
        detected = time.perf_counter() - start
        false = sum(e.kind == "released" for e in events)
        print(
            f"1 h handling at {rate_hz} Hz ({samples.size} samples): generate {generated:.2f} s, "
            f"detect {detected:.2f} s, false releases {false}"
        )
        figures[f"handling_hour_{rate_hz}hz"] = {
            "generate_s": generated,
            "detect_s": detected,
            "false": false,
        }
    return figures


def main() -> None:
    figures = {
        f"{axis} {rate:g} Hz {angle:g} deg": accuracy(axis, rate, angle, runs)
        for axis, rate, angle, runs in CASES
    }
    write_result(
        "release",
        "release detection on simulated decays: found, false, error against the truth, how long after the "
        "release the detector was sure, and its speed; an hour of handling without a release",
        counts={"cases": [list(case) for case in CASES]},
        figures=figures | handling_hour(),
    )


if __name__ == "__main__":
    main()
