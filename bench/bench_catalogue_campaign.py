"""A campaign's catalogue write-back, in the campaign's own process: what the parent spends (its CPU, the
catalogue writer's thread included) with no catalogue, with every file's row already there, and over files
not catalogued yet, their rows made either by the writer's thread from the files after the fits (before:
no ``file_work``) or by the workers that scan them (now: ``CatalogueWriter.file_rows``), side by side,
interleaved, in one run.

Run: .venv/bin/python bench/bench_catalogue_campaign.py [--n 360] [--repeats 3] [--jobs 2] [--data DIR]

The recordings are ``tests/campaign_scale.write_many_decays``'s (kept in --data between runs, shared with
``bench_campaign_scale.py``). The parent's CPU is ``getrusage(RUSAGE_SELF)`` around ``tankdaq.campaign``
and the writer's close, the workers' ``RUSAGE_CHILDREN`` (the pool's workers are reaped when the campaign
ends). CPU, not wall, is the figure to read on a shared machine. It also says what ``catalogue index``
of the same files into a new catalogue costs. Medians of --repeats; what users need of them is in
docs/performance.md.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import datetime
import platform
import resource
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import sqlalchemy as sa

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from benchjson import write_result
from support.campaign_scale import write_many_decays
from tankdaq.api.campaigns import campaign
from tankdaq.catalogue.database import open_catalogue
from tankdaq.catalogue.hooks import CatalogueWriter
from tankdaq.catalogue.index import index_folder
from tankdaq.catalogue.schema import decays

MODES = (
    "no catalogue",
    "rows exist",
    "new rows, made by the writer (before)",
    "new rows, made by the workers (now)",
)


def cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def run(folder: Path, jobs: int, url: str | None, in_workers: bool) -> tuple[float, float, float, list[str]]:
    """One campaign with the CLI's catalogue hooks: (wall s, parent CPU s, workers CPU s, lines said)."""
    lines: list[str] = []
    wall, own, theirs = time.perf_counter(), cpu(resource.RUSAGE_SELF), cpu(resource.RUSAGE_CHILDREN)
    with CatalogueWriter(url, lines.append) as writer:
        hook: Callable | None = (lambda fit: writer.add_campaign([fit])) if writer.enabled else None
        rows = writer.file_rows() if writer.enabled and in_workers else None
        campaign(folder, jobs=jobs, on_result=hook, file_work=rows)
    return (
        time.perf_counter() - wall,
        cpu(resource.RUSAGE_SELF) - own,
        cpu(resource.RUSAGE_CHILDREN) - theirs,
        lines,
    )


def count(url: str) -> int:
    with open_catalogue(url) as catalogue, catalogue.reading() as connection:
        return int(connection.execute(sa.select(sa.func.count()).select_from(decays)).scalar() or 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=360)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "tankdaq-campaign-scale")
    args = parser.parse_args()
    folder = args.data / str(args.n)
    if len(list(folder.rglob("*.mcap"))) != args.n:
        write_many_decays(folder, args.n)
    print(
        f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, "
        f"{platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, N = {args.n}, --jobs {args.jobs}, "
        f"load average at start {', '.join(f'{x:.1f}' for x in os.getloadavg())}",
        flush=True,
    )
    figures: dict[str, list[tuple[float, float, float]]] = {mode: [] for mode in MODES}
    with tempfile.TemporaryDirectory() as tmp:
        existing = f"sqlite:///{tmp}/existing.sqlite"
        own = cpu(resource.RUSAGE_SELF)
        with open_catalogue(existing) as catalogue:
            index_folder(catalogue, folder)  # a new catalogue: every file's row made and written
        indexed = cpu(resource.RUSAGE_SELF) - own
        per_file_ms = 1000 * indexed / args.n
        print(f"catalogue index of the {args.n} files: {indexed:.2f} s CPU, {per_file_ms:.2f} ms a file")
        run(folder, args.jobs, None, False)  # not timed: the kernels loaded, the caches warm
        for repeat in range(args.repeats):
            for number, mode in enumerate(MODES):
                fresh = f"sqlite:///{tmp}/new-{repeat}-{number}.sqlite"
                url = {MODES[0]: None, MODES[1]: existing}.get(mode, fresh)
                wall, own, theirs, lines = run(
                    folder, args.jobs, url, mode != MODES[2]
                )  # as the CLI, but before
                if lines or (url is not None and count(url) != args.n):
                    raise RuntimeError(f"{mode}: {lines} / {url and count(url)} rows, not {args.n}")
                figures[mode].append((wall, own, theirs))
    print("\n| catalogue | wall s | parent CPU s | workers CPU s | parent CPU over none, ms per decay |")
    print("|---|---:|---:|---:|---:|")
    none = statistics.median(f[1] for f in figures[MODES[0]])
    results: dict[str, object] = {"catalogue_index_ms_per_file": per_file_ms}
    for mode in MODES:
        wall, own, theirs = (statistics.median(f[i] for f in figures[mode]) for i in range(3))
        extra = 1000 * (own - none) / args.n
        print(f"| {mode} | {wall:.2f} | {own:.2f} | {theirs:.2f} | {extra:.2f} |")
        results[mode] = {
            "wall_s": wall,
            "parent_cpu_s": own,
            "workers_cpu_s": theirs,
            "parent_cpu_over_none_ms_per_decay": extra,
        }
    write_result(
        "catalogue_campaign",
        "a campaign's catalogue write-back in the campaign's own process: the parent's CPU with no "
        "catalogue, with every row already there, and over files not catalogued yet (rows by the writer or "
        "the workers)",
        counts={"n": args.n, "repeats": args.repeats, "jobs": args.jobs},
        figures=results,
        baseline=f"{MODES[0]} (parent CPU over it), same run",
    )
    print(f"\nload average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
