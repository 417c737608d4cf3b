"""The Python API's costs: ``import tankdaq`` against bare Python, and ``tankdaq.identify`` in a warm
process against ``tankdaq identify --json`` started afresh, on one simulated recording.

Run: OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_api.py   (about a minute; without that variable
OpenBLAS's spinning threads count as the warm process's CPU: 1.3 s, not 0.15 s). CPU time (user +
system) of child processes, median and least of REPEATS interleaved starts, bytecode compiled first
(PYTHONDONTWRITEBYTECODE dropped); ``BASELINE_SRC=/tmp/base/src`` adds the ``import tankdaq`` of another
tree (a ``git archive`` of main).
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import tankdaq
from benchjson import write_result

REPEATS = 11
CHILD_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def child_cpu_s(argv: list[str], env: dict[str, str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, check=True, capture_output=True, env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def starts(lines: dict[str, tuple[list[str], dict[str, str]]]) -> dict[str, dict[str, float]]:
    """Each line started REPEATS times, interleaved; median and least CPU."""
    for argv, env in lines.values():
        child_cpu_s(argv, env)  # bytecode written once
    times: dict[str, list[float]] = {name: [] for name in lines}
    for _ in range(REPEATS):
        for name, (argv, env) in lines.items():
            times[name].append(child_cpu_s(argv, env))
    for name, found in times.items():
        print(f"{name:<40} median {statistics.median(found) * 1e3:7.1f} ms  least {min(found) * 1e3:7.1f} ms")
    return {
        name: {"median_ms_cpu": statistics.median(found) * 1e3, "least_ms_cpu": min(found) * 1e3}
        for name, found in times.items()
    }


def main() -> None:
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; {sys.version.split()[0]}")
    python = sys.executable
    lines = {
        "python -c pass": ([python, "-c", "pass"], CHILD_ENV),
        "python -c 'import tankdaq'": ([python, "-c", "import tankdaq"], CHILD_ENV),
    }
    baseline = os.environ.get("BASELINE_SRC")
    if baseline:
        lines["import tankdaq (BASELINE_SRC)"] = (
            [python, "-c", "import tankdaq"],
            {**CHILD_ENV, "PYTHONPATH": baseline},
        )
    figures: dict[str, dict[str, float]] = starts(lines)
    with tempfile.TemporaryDirectory() as folder:
        (rec,) = tankdaq.simulate(folder, seed=7)
        tankdaq.identify(rec)  # kernels and imports loaded once
        spent = []
        for _ in range(5):
            began = time.process_time()
            tankdaq.identify(rec)
            spent.append(time.process_time() - began)
        print(f"{'tankdaq.identify(rec), warm process':<40} median {statistics.median(spent) * 1e3:7.1f} ms")
        figures["tankdaq.identify(rec), warm process"] = {"median_ms_cpu": statistics.median(spent) * 1e3}
        command = str(Path(python).with_name("tankdaq"))
        figures |= starts(
            {
                "tankdaq identify --json (fresh process)": (
                    [command, "identify", "--json", str(rec.path)],
                    CHILD_ENV,
                )
            }
        )
    bare = figures["python -c pass"]["median_ms_cpu"]
    write_result(
        "api",
        "CPU time (user + system) of `import tankdaq` against bare Python, and tankdaq.identify in a warm "
        "process "
        "against `tankdaq identify --json` started afresh, on one simulated recording",
        counts={"repeats": REPEATS},
        figures=figures,
        ratios={f"{name} over python -c pass": row["median_ms_cpu"] / bare for name, row in figures.items()},
        baseline="`python -c pass`, interleaved in the same run",
    )


if __name__ == "__main__":
    main()
