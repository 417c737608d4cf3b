"""Campaign cost against N: ``--jobs 1``, ``--jobs 2`` and a 2-worker Dask cluster side by side in one run.

Run: .venv/bin/python bench/bench_campaign_scale.py [--sizes 36,360,3600] [--repeats 3] [--data DIR]
[--out FILE.md] [--baseline SRC] [--no-work] [--no-command] [--modes "--jobs 2"]   (N = 3600 takes
about 15 minutes on a loaded 2-core machine). Two tables, markdown, printed and written to --out:

1. The work (scan and fit, no report) in this process, the executor already started (the pool forked,
   the client connected to a real ``dask scheduler`` with two ``dask worker`` processes): wall, the
   parent's (the Dask client's) CPU, the workers' CPU, and the ratios ``--jobs 1`` / ``--jobs 2`` and
   Dask / ``--jobs 2``; median of --repeats, the modes interleaved. A fourth row is the machine's own
   ceiling for that ratio: two ``--jobs 1`` campaigns of N at once, in two forked processes (``2 x
   --jobs 1`` wall over the slower one's wall): what two cores give this work with no pool at all.
2. ``tankdaq campaign DIR`` end to end (process start included), one run per N and mode: wall, CPU
   (the command and its reaped workers; Dask workers measured apart), peak RSS of the command and the
   sum of its workers' (sampled every 50 ms). With --baseline SRC (``git archive COMMIT src | tar -x -C
   /tmp/base``; SRC=/tmp/base/src) the same command of that code runs beside it.

The recordings (``tests/campaign_scale.write_many_decays``: groups of two, 3 hulls x 3 drafts, 5 s at
100 Hz, MCAP) are kept in --data between runs. On a machine shared with other jobs wall time measures
the neighbours too: compare ratios within one run, and quote the load average printed with them.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import datetime
import gc
import multiprocessing
import platform
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
from typing import Any

import psutil

from benchjson import write_result

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support.campaign_scale import dask_cluster, write_many_decays
from tankdaq.campaign.executors import campaign_executor
from tankdaq.campaign.groups import find_recordings
from tankdaq.campaign.stream import fit_campaign, scan_campaign

TANKDAQ = [sys.executable, "-c", "from tankdaq.cli import main; main()"]
MODES = ("--jobs 1", "--jobs 2", "dask, 2 workers")
CEILING = "two --jobs 1 at once (the machine's ceiling)"
SAMPLE_S = 0.05
#: The campaign whose first run warms each executor and tree (not timed).
WARM_N = 36


def decays(data: Path, n: int) -> Path:
    """The folder of ``n`` recordings, written once."""
    folder = data / str(n)
    if len(list(folder.rglob("*.mcap"))) != n:
        write_many_decays(folder, n)
    return folder


def cpu_of(processes: list[psutil.Process]) -> float:
    total = 0.0
    for process in processes:
        try:
            times = process.cpu_times()
        except psutil.Error:
            continue
        total += times.user + times.system
    return total


def self_cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime


def workers_of(executor: object, dask_pids: list[int]) -> list[psutil.Process]:
    """The worker processes: the pool's children of this process, or the Dask workers."""
    if dask_pids:
        return [psutil.Process(pid) for pid in dask_pids]
    return psutil.Process().children(recursive=True) if executor is not None else []


def work(folder: Path, executor: Executor | None) -> int:
    paths = find_recordings([folder])
    scan = scan_campaign(paths, executor=executor)
    return sum(1 for _ in fit_campaign(scan.groups(), executor=executor))


def timed_serial_work(folder: Path) -> tuple[float, float]:
    """(wall, CPU) of ``--jobs 1``'s work in this process: one of the two at once of the ceiling row."""
    wall, cpu = time.perf_counter(), time.process_time()
    work(folder, None)
    return time.perf_counter() - wall, time.process_time() - cpu


def two_at_once(folder: Path) -> tuple[float, float, float]:
    """The ceiling row: two serial campaigns at once in forked processes (the kernels loaded here)."""
    gc.freeze()  # forked as the local pool forks (``campaign.executors.campaign_executor``)
    try:
        pool = multiprocessing.get_context("fork").Pool(2)
        pool.map(int, [0, 1])  # both forked and started before the clock
    finally:
        gc.unfreeze()
    with pool:
        results = pool.map(timed_serial_work, [folder, folder])
    return max(wall for wall, _ in results), 0.0, sum(cpu for _, cpu in results)


def executors(address: str) -> dict[str, Callable[[], AbstractContextManager]]:
    return {
        "--jobs 1": lambda: campaign_executor(1),
        "--jobs 2": lambda: campaign_executor(2),
        "dask, 2 workers": lambda: campaign_executor(scheduler=address),
    }


def work_table(
    sizes: list[int], data: Path, repeats: int, address: str, dask_pids: list[int], results: dict[str, Any]
) -> str:
    """Table 1: the work in this process, the executor started; medians of ``repeats``, interleaved."""
    lines = [
        "| N | where | wall s | parent (client) CPU s | workers CPU s | jobs1/jobs2 wall | dask/jobs2 wall |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for n in sizes:
        folder = decays(data, n)
        figures: dict[str, list[tuple[float, float, float]]] = {mode: [] for mode in (*MODES, CEILING)}
        warm = decays(data, WARM_N)
        for _ in range(repeats):
            for mode, make in executors(address).items():
                with make() as executor:
                    work(warm, executor)  # the workers' first task (imports, kernels) is not timed
                    workers = workers_of(executor, dask_pids if mode.startswith("dask") else [])
                    wall, own, theirs = time.perf_counter(), self_cpu(), cpu_of(workers)
                    work(folder, executor)
                    figures[mode].append(
                        (time.perf_counter() - wall, self_cpu() - own, cpu_of(workers) - theirs)
                    )
            figures[CEILING].append(two_at_once(folder))
        median = {
            mode: [statistics.median(f[i] for f in runs) for i in range(3)] for mode, runs in figures.items()
        }
        serial = median["--jobs 1"][0]
        for mode in (*MODES, CEILING):
            wall, own, theirs = median[mode]
            speedup = f"{serial / wall:.2f}×" if mode == "--jobs 2" else ""
            speedup = f"{2 * serial / wall:.2f}× (ceiling)" if mode == CEILING else speedup
            dask = f"{wall / median['--jobs 2'][0]:.2f}×" if mode.startswith("dask") else ""
            lines.append(f"| {n} | {mode} | {wall:.2f} | {own:.2f} | {theirs:.2f} | {speedup} | {dask} |")
            results[f"work n{n} {mode}"] = {"wall_s": wall, "parent_cpu_s": own, "workers_cpu_s": theirs}
        results[f"work n{n} ratios"] = {
            "jobs1_over_jobs2_wall": serial / median["--jobs 2"][0],
            "ceiling_2x_jobs1_over_two_at_once_wall": 2 * serial / median[CEILING][0],
            "dask_over_jobs2_wall": median[MODES[-1]][0] / median["--jobs 2"][0],
        }
        print("\n".join(lines[-4:]), flush=True)
    return "\n".join(lines)


def command(folder: Path, mode: str, address: str, dask_pids: list[int], src: str | None) -> list[float]:
    """[wall s, command's own CPU s, workers' CPU s, command's peak RSS MB, workers' peak RSS MB (sum)]
    of one ``tankdaq campaign`` (process start included)."""
    on_dask = mode.startswith("dask")
    options = ["--executor", "dask", "--scheduler", address] if on_dask else ["--jobs", mode.split()[-1]]
    env = {**os.environ, "PYTHONPATH": src} if src else dict(os.environ)
    dask_workers = [psutil.Process(pid) for pid in dask_pids] if on_dask else []
    before = cpu_of(dask_workers)
    own = parent_peak = workers_peak = 0.0
    with tempfile.TemporaryFile() as out:
        wall = time.perf_counter()
        child = subprocess.Popen(
            [*TANKDAQ, "campaign", str(folder), *options], stdout=out, stderr=out, env=env
        )
        watched = psutil.Process(child.pid)
        while not (done := os.wait4(child.pid, os.WNOHANG))[0]:
            try:
                own = sum(watched.cpu_times()[:2])
                parent_peak = max(parent_peak, watched.memory_info().rss)
                workers = watched.children(recursive=True) or dask_workers
                workers_peak = max(workers_peak, sum(w.memory_info().rss for w in workers))
            except psutil.Error:
                pass
            time.sleep(SAMPLE_S)  # sampling memory and CPU while the command runs
        wall = time.perf_counter() - wall
        child.returncode = os.waitstatus_to_exitcode(done[1])
        if child.returncode != 0:
            out.seek(0)
            raise RuntimeError(f"tankdaq campaign {' '.join(options)} failed: {out.read()[-2000:]!r}")
    total = done[2].ru_utime + done[2].ru_stime  # the command and its reaped pool workers
    workers_cpu = cpu_of(dask_workers) - before if on_dask else total - own
    return [wall, own, workers_cpu, parent_peak / 2**20, workers_peak / 2**20]


def command_table(
    sizes: list[int],
    data: Path,
    address: str,
    dask_pids: list[int],
    baseline: str | None,
    modes: list[str],
    results: dict[str, Any],
) -> str:
    """Table 2: ``tankdaq campaign`` end to end, this tree (and --baseline's), one run per N and mode."""
    lines = [
        "| N | tree | where | wall s | command CPU s | workers CPU s | command peak RSS MB "
        "| workers peak RSS MB |",
        "|---:|---|---|---:|---:|---:|---:|---:|",
    ]
    trees = [("this tree", os.environ.get("PYTHONPATH"))] + ([("baseline", baseline)] if baseline else [])
    for _, src in trees:  # not timed: a tree's first command may build its kernels, fill caches
        command(decays(data, WARM_N), "--jobs 1", address, dask_pids, src)
    for n in sizes:
        folder = decays(data, n)
        for tree, src in trees:
            for mode in modes:
                wall, own, theirs, parent_mb, workers_mb = command(folder, mode, address, dask_pids, src)
                lines.append(
                    f"| {n} | {tree} | {mode} | {wall:.2f} | {own:.2f} | {theirs:.2f} "
                    f"| {parent_mb:.0f} | {workers_mb:.0f} |"
                )
                print(lines[-1], flush=True)
                results[f"command n{n} {tree} {mode}"] = {
                    "wall_s": wall,
                    "command_cpu_s": own,
                    "workers_cpu_s": theirs,
                    "command_peak_rss_mb": parent_mb,
                    "workers_peak_rss_mb": workers_mb,
                }
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="36,360,3600")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "tankdaq-campaign-scale")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--baseline", help="src/ of an earlier commit: its command beside this one")
    parser.add_argument("--no-command", action="store_true", help="only the in-process table")
    parser.add_argument("--no-work", action="store_true", help="only the command table")
    parser.add_argument("--modes", default=",".join(MODES), help=f"some of: {', '.join(MODES)}")
    args = parser.parse_args()
    sizes = [int(n) for n in args.sizes.split(",")]
    header = (
        f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, "
        f"{platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, load average at start "
        + ", ".join(f"{x:.1f}" for x in os.getloadavg())
    )
    print(header, flush=True)
    with tempfile.TemporaryDirectory() as tmp, dask_cluster(2, Path(tmp)) as (address, processes):
        dask_pids = [p.pid for p in processes[1:]]
        tables, results = [header], {}
        if not args.no_work:
            tables += ["", work_table(sizes, args.data, args.repeats, address, dask_pids, results)]
        if not args.no_command:
            modes = [
                mode
                for mode in MODES
                if any(mode.startswith(given.strip()) for given in args.modes.split(",") if given.strip())
            ]
            tables += ["", command_table(sizes, args.data, address, dask_pids, args.baseline, modes, results)]
        tables.append(f"\nload average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    text = "\n".join(tables) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)
    write_result(
        "campaign_scale",
        "campaign scan and fit of N synthetic decays: --jobs 1, --jobs 2 and a 2-worker Dask cluster in this "
        "process (medians, interleaved; two serial campaigns at once as the machine's ceiling), and the "
        "`tankdaq campaign` command end to end with peak RSS",
        counts={
            "sizes": sizes,
            "repeats": args.repeats,
            "command": not args.no_command,
            "work": not args.no_work,
        },
        figures=results,
        baseline=f"--baseline {args.baseline} (command rows 'baseline')" if args.baseline else None,
    )


if __name__ == "__main__":
    main()
