"""Campaign throughput: 36 recordings (3 hulls x 3 drafts x 4 angles, MCAP) read, fitted and reported.

Run: .venv/bin/python bench/bench_campaign.py   (about a minute). Prints, for the whole pipeline (read,
fit, report with plots): wall and CPU time (this process and its reaped workers) serially in one process,
on a process pool of 1, 2 and N workers, on a local Dask cluster of 1, 2 and N worker processes, and the
``tankdaq campaign --report`` command end to end (process start and imports included) with --jobs 1 and N,
and beside it the same command of an earlier commit when BASELINE_SRC names its src/ folder
(``git archive COMMIT src | tar -x -C /tmp/base``; BASELINE_SRC=/tmp/base/src). On a machine shared with
other jobs wall time measures the neighbours too; the CPU column does not.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import Executor
from contextlib import AbstractContextManager
from pathlib import Path

from benchjson import write_result
from tankdaq.campaign.executors import campaign_executor
from tankdaq.campaign.groups import find_recordings, group_runs, identify_groups, read_campaign_runs
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.viz.campaign_report import load_plotting, write_report

HULLS = ("trimaran", "catamaran", "swath")
DRAFTS = (0.9, 1.0, 1.1)
ANGLES_DEG = (2.0, 4.0, 6.0, 8.0)
CORES = os.cpu_count() or 1
REPEATS = 3
#: ``tankdaq`` of whichever tankdaq PYTHONPATH gives (the venv's console script ignores it).
TANKDAQ = [sys.executable, "-c", "from tankdaq.cli import main; main()"]


def cpu_s() -> float:
    """CPU seconds of this process and of its finished children (pool workers once the pool is shut)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def pipeline(folder: Path, reports: Path, executor: Executor | None) -> int:
    """Read, fit and report the campaign; the report into a new folder under ``reports`` (tankdaq never
    writes over a report)."""
    reports.mkdir(exist_ok=True)
    report = Path(tempfile.mkdtemp(dir=reports))
    paths = find_recordings([folder])
    read = map if executor is None else executor.map
    runs = [run for found in read(read_campaign_runs, paths) for run in found]
    results = identify_groups(group_runs(runs), executor=executor)
    write_report(results, report, executor)
    return len(paths)


def timed(
    label: str, folder: Path, report: Path, make_executor: Callable[[], AbstractContextManager]
) -> dict[str, float]:
    wall, cpu = time.perf_counter(), cpu_s()
    with make_executor() as executor:
        n = pipeline(folder, report, executor)
    wall, cpu = time.perf_counter() - wall, cpu_s() - cpu
    print(f"{label:<28} {wall:6.2f} s wall {cpu:6.2f} s CPU  {n / wall:5.1f} recordings/s wall")
    return {"wall_s": wall, "cpu_s": cpu, "recordings_per_s_wall": n / wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=REPEATS, help="runs of each command line")
    repeats = parser.parse_args().repeats
    figures: dict[str, dict[str, float]] = {}
    print(f"machine: {CORES} cores, load {os.getloadavg()[0]:.1f}; {sys.version.split()[0]}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "campaign"
        write_simulated_campaign(folder, HULLS, "pitch", DRAFTS, ANGLES_DEG, "mcap", seed=0)
        report = Path(tmp) / "report"
        pipeline(folder, report, None)  # compiled kernels, font cache
        figures["serial"] = timed("serial (one process)", folder, report, lambda: campaign_executor(1))
        for jobs in sorted({1, 2, CORES}):
            figures[f"pool_{jobs}"] = timed(f"process pool, {jobs} workers", folder, report, _pool(jobs))
        try:
            from distributed import LocalCluster
        except ImportError:
            print("dask: not installed (pip install 'tankdaq[dask]')")
        else:
            for workers in sorted({1, 2, CORES}):
                with LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=None) as cluster:
                    address = cluster.scheduler_address
                    figures[f"dask_{workers}"] = timed(
                        f"dask, {workers} worker processes",
                        folder,
                        report,
                        lambda a=address: campaign_executor(scheduler=a),
                    )
        figures |= command_lines(folder, Path(tmp) / "cli-report", repeats)
    serial = figures["serial"]["wall_s"]
    write_result(
        "campaign",
        "a campaign of 36 MCAP recordings read, fitted and reported (plots): serial, process pools, a local "
        "Dask cluster, and the `tankdaq campaign --report` command end to end",
        counts={"recordings": len(HULLS) * len(DRAFTS) * len(ANGLES_DEG), "command_repeats": repeats},
        figures=figures,
        ratios={
            f"{name}_wall_over_serial": row["wall_s"] / serial
            for name, row in figures.items()
            if name.startswith(("pool", "dask"))
        },
        baseline="serial in one process, same run",
    )


def command_lines(folder: Path, report: Path, repeats: int) -> dict[str, dict[str, float]]:
    """``tankdaq campaign --report`` end to end (process start and imports included), --jobs 1 and N,
    REPEATS times interleaved; with BASELINE_SRC (a ``git archive`` of an earlier commit's src/) the
    same command lines of that code beside them, in the same run."""
    trees = [("this tree", os.environ.get("PYTHONPATH"))]
    if os.environ.get("BASELINE_SRC"):
        trees.append(("baseline", os.environ["BASELINE_SRC"]))
    lines = [(tree, path, jobs) for tree, path in trees for jobs in sorted({1, CORES})]
    walls: dict[int, list[float]] = {i: [] for i in range(len(lines))}
    cpus: dict[int, list[float]] = {i: [] for i in range(len(lines))}
    for _ in range(repeats):
        for i, (_, path, jobs) in enumerate(lines):
            env = {**os.environ, "PYTHONPATH": path} if path else dict(os.environ)
            wall, cpu = time.perf_counter(), cpu_s()
            subprocess.run(
                [
                    *TANKDAQ,
                    "campaign",
                    folder,
                    "--report",
                    report / f"{len(walls[i])}-{i}",
                    "--jobs",
                    str(jobs),
                ],
                check=True,
                capture_output=True,
                env=env,
            )
            walls[i].append(time.perf_counter() - wall)
            cpus[i].append(cpu_s() - cpu)
    figures = {}
    for i, (tree, _, jobs) in enumerate(lines):
        wall, cpu = statistics.median(walls[i]), statistics.median(cpus[i])
        figures[f"command --jobs {jobs} ({tree})"] = {"wall_s": wall, "cpu_s": cpu}
        print(
            f"tankdaq campaign --jobs {jobs} ({tree}): median {wall:5.2f} s wall "
            f"(best {min(walls[i]):5.2f}), {cpu:5.2f} s CPU, process start included"
        )
    return figures


def _pool(jobs: int) -> Callable[[], AbstractContextManager]:
    return lambda: campaign_executor(jobs, prepare=[load_plotting])


if __name__ == "__main__":
    main()
