"""The first run after a pip install: building the native kernels into a fresh user cache (issue 23).

Run: .venv/bin/python bench/bench_first_run.py   (one to three minutes). Each repeat builds the native
module in a fresh process into a fresh ``TANKDAQ_CACHE_DIR`` (what ``tankdaq demo`` does first on a new
machine) and reports its wall and CPU time (user + system of the child, which includes the
``check_runs_here`` grandchild) and the module's size: the figures the first-run line states.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchjson import write_result

REPEATS = 3
BUILD = (
    "from tankdaq.ident import compiled as c; "
    "r = c.ensure_native(); assert r is None, r; print(c.native_path())"
)


def build_once() -> tuple[float, float, int]:
    """(wall s, CPU s, module bytes) of one build into a fresh cache folder."""
    with tempfile.TemporaryDirectory() as cache:
        env = {k: v for k, v in os.environ.items() if k != "TANKDAQ_KERNEL_DIR"}
        env["TANKDAQ_CACHE_DIR"] = cache
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-c", BUILD], env=env, capture_output=True, text=True, check=True
        )
        wall = time.perf_counter() - started
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        size = Path(done.stdout.strip()).stat().st_size
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=REPEATS)
    repeats = parser.parse_args().repeats
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; {sys.version.split()[0]}")
    runs = [build_once() for _ in range(repeats)]
    walls, cpus, sizes = zip(*runs, strict=True)
    print(f"build wall s: median {statistics.median(walls):.1f}, least {min(walls):.1f}")
    print(f"build CPU s:  median {statistics.median(cpus):.1f}, least {min(cpus):.1f}")
    print(f"module size:  {max(sizes) / 1e6:.2f} MB")
    print(f"load after:   {os.getloadavg()[0]:.1f}")
    write_result(
        "first_run",
        "building the native kernels into a fresh cache in a fresh process (a first run after pip install)",
        counts={"repeats": repeats},
        figures={
            "build_wall_s_median": statistics.median(walls),
            "build_wall_s_least": min(walls),
            "build_cpu_s_median": statistics.median(cpus),
            "build_cpu_s_least": min(cpus),
            "module_mb": max(sizes) / 1e6,
        },
    )


if __name__ == "__main__":
    main()
