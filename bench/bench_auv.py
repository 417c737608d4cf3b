"""AUV diving-plane pipeline on one core: simulate -> write/read MCAP -> identify -> sensitivity.

Prints the time of each stage (median of a few repeats, in-process, after a warm-up that loads or
compiles the numba integrator) and of the same pipeline through the installed ``tankdaq auv`` commands
(process start-up and imports included). Target: the whole pipeline within 10 s on one core.
Run: .venv/bin/python bench/bench_auv.py
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"
_CORE = min(os.sched_getaffinity(0))
os.sched_setaffinity(0, {_CORE})

import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from benchjson import write_result  # noqa: E402
from tankdaq.auv.identify import SeparateIdentifier  # noqa: E402
from tankdaq.auv.io import read_record, write_record  # noqa: E402
from tankdaq.auv.model import add_noise, simulate_zigzag  # noqa: E402
from tankdaq.auv.sensitivity import sensitivity_analysis  # noqa: E402
from tankdaq.auv.vehicle import load_vehicle  # noqa: E402

REPEATS = 3
DELTA_RAD, THETA_RAD = np.radians(15.0), np.radians(10.0)


def pipeline(folder: Path) -> dict[str, float]:
    """One run of every stage; seconds per stage."""
    times: dict[str, float] = {}
    start = time.perf_counter()
    vehicle = load_vehicle("nps_auv2")
    record = add_noise(simulate_zigzag(vehicle, DELTA_RAD, THETA_RAD, rate_hz=100.0), 1.0, seed=0)
    times["simulate (8 reversals, 100 Hz, noise)"] = time.perf_counter() - start
    start = time.perf_counter()
    path = write_record(
        Path(tempfile.mkdtemp(dir=folder)) / "zigzag.mcap", record, vehicle
    )  # never over a file
    back = read_record(path)
    times["write + read MCAP"] = time.perf_counter() - start
    start = time.perf_counter()
    SeparateIdentifier(vehicle, method="lssvm").fit(back)
    times["identify (LS-SVM, 25 gammas x 5 folds)"] = time.perf_counter() - start
    start = time.perf_counter()
    SeparateIdentifier(vehicle, method="ols").fit(back)
    times["identify (OLS)"] = time.perf_counter() - start
    start = time.perf_counter()
    sensitivity_analysis(vehicle, DELTA_RAD, THETA_RAD)
    times["sensitivity (11 derivatives x 2 + 1 runs)"] = time.perf_counter() - start
    return times


def cli_pipeline(folder: Path) -> tuple[float, float] | None:
    """The same pipeline through the installed console script, pinned to the same core: wall and CPU s."""
    script = Path(sys.executable).with_name("tankdaq")
    if not script.exists():
        return None
    pin = ["taskset", "-c", str(_CORE)] if shutil.which("taskset") else []
    record = str(folder / "cli.mcap")
    commands = [
        ["auv", "simulate", "--noise", "realistic", "--out", record],
        ["auv", "identify", record, "--no-sensitivity"],
        ["auv", "sensitivity"],
    ]
    start, cpu_start = time.perf_counter(), _children_cpu_s()
    for command in commands:
        subprocess.run([*pin, str(script), *command], check=True, capture_output=True)
    return time.perf_counter() - start, _children_cpu_s() - cpu_start


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        start = time.perf_counter()
        pipeline(folder)
        warm_up = time.perf_counter() - start
        runs = [pipeline(folder) for _ in range(REPEATS)]
        cli = cli_pipeline(folder)
    print(f"AUV diving-plane pipeline, one core (cpu {_CORE}), median of {REPEATS} runs after warm-up")
    total = 0.0
    figures: dict[str, float] = {}
    for stage in runs[0]:
        median = figures[f"{stage}: s"] = float(np.median([run[stage] for run in runs]))
        if "OLS" not in stage:
            total += median
        print(f"  {stage:<45} {median:8.3f} s")
    figures |= {"pipeline_total_s": total, "first_run_s": warm_up}
    print(f"  {'pipeline total (simulate, io, LS-SVM, sensitivity)':<45} {total:8.3f} s   (target <= 10 s)")
    print(f"  {'first run (numba cache load or compile)':<45} {warm_up:8.3f} s")
    if cli is not None:
        wall, cpu = cli
        print(
            f"  {'CLI: simulate + identify + sensitivity':<45} {wall:8.3f} s   wall, {cpu:.3f} s CPU "
            "(3 processes, imports included)"
        )
        figures |= {"cli_wall_s": wall, "cli_cpu_s": cpu}
    write_result(
        "auv",
        "the AUV diving-plane pipeline on one core (simulate, MCAP write and read, identify, sensitivity; "
        "median after a warm-up) and the same through the `tankdaq auv` commands",
        counts={"repeats": REPEATS},
        figures=figures,
    )


if __name__ == "__main__":
    main()
