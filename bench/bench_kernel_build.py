"""The native kernels' build CPU and their run time, this tree's against main's, in the same run (issue 43).

Run: .venv/bin/python bench/bench_kernel_build.py [--builds 2] [--rounds 9] [--baseline-ref main]
(several minutes). main's ``src`` is exported with ``git archive`` into a temporary folder; each build
runs ``compiled.build`` in a fresh process into a fresh folder, main's and this tree's alternately, and
its CPU is user + system of that child and its grandchildren (``check_runs_here``, pycc's C compiler).
Then each module's kernels are timed on ``compiled.example_calls()``: every round starts one fresh
process per module, in a shuffled order, each timing every kernel (thread CPU time per call, the median
of 7 repeats); a ratio is this tree's over main's within one round, reported as the median and quartiles
over the rounds (the machine's load moves both of a round alike). The outputs, and those of a realistic
output-error and equation-error fit run on each module, must be equal bit for bit (``np.array_equal``).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import random
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import Progress

from benchjson import write_result

REPO = Path(__file__).resolve().parent.parent
BUILD = "from tankdaq.ident import compiled as c; print(c.build())"
#: Timed in each child: load the module given, time every example call, run the realistic fits.
TIME_KERNELS = r"""
import json, pickle, sys, time
from pathlib import Path
from tankdaq.ident import compiled
sys.path.insert(0, sys.argv[3])
assert compiled.use_native(Path(sys.argv[1])), "it does not load"
module = compiled._loaded.source
times, outputs = {}, {}
for name, args in compiled.example_calls().items():
    kernel = getattr(module, name)
    outputs[name] = kernel(*args)
    per_call = []
    for _ in range(7):
        started = time.thread_time()
        for _ in range(int(sys.argv[4])):
            kernel(*args)
        per_call.append((time.thread_time() - started) / int(sys.argv[4]))
    times[name] = sorted(per_call)[3]
from bench_ident import TRUTH, decay
from tankdaq.ident.equation_error import EquationErrorFit
from tankdaq.ident.output_error import OutputErrorFit
run = decay(TRUTH, seed=1)
for estimator in (OutputErrorFit, EquationErrorFit):
    fitted = estimator(("b1", "b2", "b3", "c1", "c2", "c3", "fc")).fit([run])
    outputs[estimator.__name__] = {k: v for k, v in vars(fitted).items() if hasattr(v, "shape")}
Path(sys.argv[2]).write_bytes(pickle.dumps(outputs))
print(json.dumps(times))
"""


def export_main(ref: str, into: Path) -> Path:
    """``git archive <ref> src`` unpacked under ``into``: the baseline's source."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", ref, "src"], capture_output=True, check=True)
    tar_path = into / "main.tar"
    tar_path.write_bytes(archive.stdout)
    with tarfile.open(tar_path) as tar:
        tar.extractall(into, filter="data")
    return into / "src"


def build(src: Path, folder: Path) -> tuple[Path, float, float]:
    """(module, CPU s, wall s) of one fresh build of ``src``'s kernels into the empty ``folder``."""
    env = dict(
        os.environ, PYTHONPATH=str(src), TANKDAQ_KERNEL_DIR=str(folder), NUMBA_CACHE_DIR=str(folder / "nc")
    )
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", BUILD], env=env, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return Path(done.stdout.strip().splitlines()[-1]), cpu, wall


def time_kernels(module: Path, outputs: Path, calls: int) -> dict[str, float]:
    """Thread CPU s per call of each kernel of ``module`` in a fresh process (outputs to ``outputs``)."""
    env = dict(os.environ, PYTHONPATH=str(REPO / "src"))
    done = subprocess.run(
        [sys.executable, "-c", TIME_KERNELS, str(module), str(outputs), str(REPO / "bench"), str(calls)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    times: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return times


def identical(a: Any, b: Any) -> bool:
    """Equal bit for bit, through tuples and dicts of arrays."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(identical(a[k], b[k]) for k in a)
    if isinstance(a, tuple):
        return len(a) == len(b) and all(identical(x, y) for x, y in zip(a, b, strict=True))
    return bool(np.array_equal(a, b))


def quartiles(values: list[float]) -> dict[str, float]:
    q1, median, q3 = np.percentile(values, [25, 50, 75])
    return {
        "median": float(median),
        "q1": float(q1),
        "q3": float(q3),
        "least": min(values),
        "most": max(values),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--builds", type=int, default=2, help="fresh builds of each (alternating)")
    parser.add_argument("--rounds", type=int, default=9, help="interleaved timing rounds")
    parser.add_argument("--calls", type=int, default=50, help="calls of a kernel per timed repeat")
    parser.add_argument("--baseline-ref", default="main")
    options = parser.parse_args()
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; {sys.version.split()[0]}")
    with tempfile.TemporaryDirectory() as tmp_name, Progress() as progress:
        tmp = Path(tmp_name)
        sources = {"baseline": export_main(options.baseline_ref, tmp), "this": REPO / "src"}
        cpu: dict[str, list[float]] = {"baseline": [], "this": []}
        wall: dict[str, list[float]] = {"baseline": [], "this": []}
        modules: dict[str, Path] = {}
        task = progress.add_task("building", total=2 * options.builds)
        for repeat in range(options.builds):
            for which, src in sources.items():
                module, cpu_s, wall_s = build(src, tmp / f"{which}{repeat}")
                modules[which] = module
                cpu[which].append(cpu_s)
                wall[which].append(wall_s)
                progress.advance(task)
        sizes = {which: module.stat().st_size / 1e6 for which, module in modules.items()}
        rounds: list[dict[str, dict[str, float]]] = []
        equal = {}
        task = progress.add_task("timing", total=options.rounds)
        for _ in range(options.rounds):
            order = list(modules)
            random.shuffle(order)
            rounds.append({w: time_kernels(modules[w], tmp / f"{w}.pkl", options.calls) for w in order})
            progress.advance(task)
        outputs = {w: pickle.loads((tmp / f"{w}.pkl").read_bytes()) for w in modules}
        equal = {
            name: identical(outputs["this"][name], outputs["baseline"][name]) for name in outputs["baseline"]
        }
    kernels = list(rounds[0]["this"])
    speed = {k: quartiles([r["this"][k] / r["baseline"][k] for r in rounds]) for k in kernels}
    run_us = {
        w: {k: statistics.median(r[w][k] for r in rounds) * 1e6 for k in kernels}
        for w in ("baseline", "this")
    }
    cpu_ratio = statistics.median(cpu["this"]) / statistics.median(cpu["baseline"])
    for which in ("baseline", "this"):
        print(f"{which:8s} build CPU s {cpu[which]}, wall s {[round(w, 1) for w in wall[which]]}")
    print(f"build CPU: this / baseline = {cpu_ratio:.2f}")
    for k in kernels:
        s = speed[k]
        spread = f"[{s['q1']:.2f}, {s['q3']:.2f}]"
        print(f"{k:28s} run time this / baseline {s['median']:.2f} {spread}, equal {equal[k]}")
    print(
        f"fits equal: {equal['OutputErrorFit']} (output error), {equal['EquationErrorFit']} (equation error)"
    )
    print(f"load after: {os.getloadavg()[0]:.1f}")
    write_result(
        "kernel_build",
        "CPU of a fresh native build of the kernels and their run time per call (example_calls), this tree "
        "against the baseline's source in the same run",
        counts={"builds": options.builds, "rounds": options.rounds, "calls": options.calls},
        figures={
            "build_cpu_s": {w: statistics.median(v) for w, v in cpu.items()},
            "build_cpu_s_each": cpu,
            "build_wall_s_median": {w: statistics.median(v) for w, v in wall.items()},
            "module_mb": sizes,
            "run_us_median": run_us,
            "bit_identical": equal,
        },
        ratios={"build_cpu": cpu_ratio, "run_time": speed},
        baseline=f"git archive {options.baseline_ref} src, built in the same run",
    )


if __name__ == "__main__":
    main()
