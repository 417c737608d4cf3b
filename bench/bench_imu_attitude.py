"""Roll from the integrated rate of turn (an IMU-class device, issue 21): accuracy over decays, and cost.

For each gyro (MTi-100 class, and the MTi-G-like default of the simulator), output rate and rest before
the tilt, SEEDS scripted roll decays (a lightly damped one, still swinging 20 s after the release) are
measured by the simulated sensor and their roll is estimated by ``device.attitude.GyroAttitude`` from
rate of turn and acceleration alone. Printed per case: over the first 20 s after the release, the RMS
error against the truth once the static error of the accelerometer's bias is set aside (median and
worst of the seeds: the must-hold is 0.1 deg), the plain RMS error (that static error included), and
the estimator's cost per sample. Run: .venv/bin/python bench/bench_imu_attitude.py
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})

import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from benchjson import write_result  # noqa: E402
from tankdaq.device.attitude import GyroAttitude  # noqa: E402
from tankdaq.physics.scenario import DecayScenario  # noqa: E402
from tankdaq.physics.sensor import GRAVITY_M_S2, SensorNoise  # noqa: E402

SEEDS = 16
WINDOW_S = 20.0
LONG_DECAY = {"b1": 0.2, "c1": 14.2185, "c3": 69.457}  # the swath's period, light damping


def one(noise: SensorNoise, rate_hz: float, release_after_s: float, seed: int) -> tuple[float, float, float]:
    """(RMS error with the static error aside, plain RMS error, both deg; seconds per sample)."""
    scenario = DecayScenario(rate_hz=rate_hz, runs=1, seed=seed, release_after_s=release_after_s,
                             decay_s=25.0, noise=noise, coefficients=LONG_DECAY)  # fmt: skip
    samples, trace = scenario.samples()
    started = time.perf_counter()
    GyroAttitude().fill(samples)
    per_sample = (time.perf_counter() - started) / samples.size
    (run,) = trace.runs
    window = slice(run.release_index, run.release_index + round(WINDOW_S * rate_hz))
    error = samples["roll"][window] - trace.angle[window]
    bias, held = scenario.sensor().acc_bias, float(run.angle0_rad or 0.0)
    static = (bias[1] * math.cos(held) - bias[2] * math.sin(held)) / GRAVITY_M_S2
    rms = math.degrees(math.sqrt(np.mean((error - static) ** 2)))
    return rms, math.degrees(math.sqrt(np.mean(error**2))), per_sample


def main() -> None:
    print(f"{SEEDS} seeds per case; RMS over the first {WINDOW_S:g} s after the release (deg)")
    print(
        "| gyro | rate | rest before tilt | bias aside: median | worst | plain: median | worst | us/sample |"
    )
    figures: dict[str, dict[str, float]] = {}
    for label, noise in (("MTi-100 0.01", SensorNoise.mti_100()), ("MTi-G 0.028", SensorNoise())):
        for rate_hz in (100.0, 400.0):
            for release_after_s in (12.0, 20.0):
                results = np.array([one(noise, rate_hz, release_after_s, seed) for seed in range(SEEDS)])
                rest = f"{release_after_s - 7:.0f}-{release_after_s - 3.5:.1f} s"  # less hold and tilt
                aside, plain, cost = np.median(results, axis=0), results.max(axis=0), np.median(results[:, 2])
                print(
                    f"| {label} | {rate_hz:.0f} | {rest} | {aside[0]:.3f} | {plain[0]:.3f} | {aside[1]:.3f} "
                    f"| {plain[1]:.3f} | {cost * 1e6:.1f} |"
                )
                figures[f"{label} {rate_hz:.0f} Hz rest {rest}"] = {
                    "rms_bias_aside_deg_median": aside[0],
                    "rms_bias_aside_deg_worst": plain[0],
                    "rms_plain_deg_median": aside[1],
                    "rms_plain_deg_worst": plain[1],
                    "us_per_sample": cost * 1e6,
                }
    write_result(
        "imu_attitude",
        "roll from the integrated rate of turn (GyroAttitude) over scripted decays: RMS error over the first "
        "20 s after the release (the accelerometer bias's static error aside, and plain), cost per sample",
        counts={"seeds": SEEDS, "window_s": WINDOW_S},
        figures=figures,
    )


if __name__ == "__main__":
    main()
