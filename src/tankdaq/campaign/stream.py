"""A campaign that streams: the parent holds each decay's group label and each group's table row, never
the recordings nor the fits' per-sample state.

Two passes over the files, both in the workers (``campaign.executors``), in chunks. The scan reads each file,
cuts its free decays and returns what groups them (hull, axis, draft, nominal angle per decay) and the
lines to say; the fit sends each worker a chunk of groups as file paths, the worker reads those files
again, fits each group and returns its row (``GroupRow``). Reading a decay twice costs less than its
fit, while handing the decays and fits to the parent would grow it by the size of every decay
(``bench/bench_campaign_scale.py``). ``fit_campaign`` yields the rows as workers
finish them, so a consumer (a table, a catalogue) can write them as they come. Whatever else a caller
wants of a file (the run catalogue: the row of a file it does not hold) is made by the worker that scans
it (``FileWork``), so the parent never reads a file.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable, Collection, Generator, Iterator, Sequence
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ..config.hulls import Hull
from ..ident.free_decay import cut_lines
from ..ident.inputs import input_notices
from ..physics.models import AUTO
from ..records import DecayRun, partial_end
from ..store.export_layout import ExportOrigin
from ..store.inputs import file_sha256
from .executors import DaskExecutor
from .groups import GroupKey, GroupResult, GroupRow, SkippedFile, fit_group, read_campaign_file, run_key

T = TypeVar("T")

#: A campaign's fits on a local pool are cut into about this many chunks (a chunk: one task for a
#: worker), so two workers share the load evenly while the per-task cost (a pickle) stays small...
CHUNKS = 32
#: ...and no chunk holds more decays (or files) than this (a worker's memory; the parent's progress).
MAX_CHUNK_DECAYS = 64
#: The scan costs about its files' bytes: one chunk per worker, of equal bytes (``scan_chunks``). On a
#: Dask cluster a task costs milliseconds of CPU between client, scheduler and worker (and a round trip),
#: so the fits too go in fewer tasks (one group can cost several times another): in chunks
#: that shrink as the work runs out, each this fraction of what is left per thread (guided
#: self-scheduling): a few large tasks first, single groups at the end, so no worker waits long on
#: another's last chunk.
DASK_GUIDED = 2


@dataclass(frozen=True)
class RunRef:
    """Where a decay is: its file, and its place among the file's cut free decays."""

    path: Path
    index: int


@dataclass(frozen=True)
class FileScan:
    """What the scan keeps of one file: its decays' group keys and the lines the campaign says of it."""

    path: Path
    keys: tuple[GroupKey, ...]  # one per decay, in file order
    notices: tuple[str, ...]  # ident.inputs.input_notices
    truncation: str | None  # the recording was cut short (meta["truncation"])
    cuts: tuple[str, ...]  # where each decay's free part was cut, and why
    sha256: str  # of its bytes: a copy among the campaign's files is read once (``store.inputs.read_twice``)
    origin: ExportOrigin | None = None  # an export's recording and releases: two exports of them, read once
    partial: tuple[tuple[int, str], ...] = ()  # decays not recorded whole: (index, how it ended, in words)


@dataclass
class CampaignScan:
    """Every file scanned (path order) and those skipped (the campaign goes on without them)."""

    files: list[FileScan]
    skipped: list[SkippedFile]

    def groups(self, include_partial: bool = False) -> dict[GroupKey, list[RunRef]]:
        """Decays by group, in sorted key order; within a group in path order (as ``group_runs``). A decay
        not recorded whole (stopped, the device gone, cut) is left out unless ``include_partial``."""
        groups: dict[GroupKey, list[RunRef]] = defaultdict(list)
        for scan in self.files:
            partial = set() if include_partial else {index for index, _ in scan.partial}
            for index, key in enumerate(scan.keys):
                if index not in partial:
                    groups[key].append(RunRef(scan.path, index))
        return dict(sorted(groups.items()))

    def partial_lines(self, included: bool) -> list[str]:
        """One line per decay not recorded whole: how it ended, and whether the campaign fits it."""
        what = "fitted as asked" if included else "left out (--include-partial fits it)"
        return [f"{scan.path.name}: {said}; {what}" for scan in self.files for _, said in scan.partial]

    @property
    def decays(self) -> int:
        return sum(len(scan.keys) for scan in self.files)

    @property
    def notices(self) -> list[str]:
        return list(dict.fromkeys(line for scan in self.files for line in scan.notices))

    @property
    def truncations(self) -> list[str]:
        return [scan.truncation for scan in self.files if scan.truncation]

    @property
    def cuts(self) -> list[str]:
        return [line for scan in self.files for line in scan.cuts]


def scan_file(path: Path, start_s: float | None = None, end_s: float | None = None) -> FileScan | SkippedFile:
    """A file's group keys and lines (``read_campaign_file``), without its samples."""
    runs = read_campaign_file(path, start_s, end_s)
    if isinstance(runs, SkippedFile):
        return runs
    truncation = next((str(r.meta["truncation"]) for r in runs if r.meta.get("truncation")), None)
    keys = tuple(run_key(run) for run in runs)
    digest = next((str(r.meta["sha256"]) for r in runs if r.meta.get("sha256")), None) or file_sha256(path)
    origin = ExportOrigin.of(runs[0].meta) if runs else None
    notices, cuts = tuple(input_notices(runs)), tuple(cut_lines(runs))
    return FileScan(path, keys, notices, truncation, cuts, digest, origin, partial_runs(runs))


def partial_runs(runs: Sequence[DecayRun]) -> tuple[tuple[int, str], ...]:
    """The decays among ``runs`` whose recording holds only part of them, with how each ended in words
    (``records.partial_end``): a campaign leaves them out unless asked."""
    return tuple((index, said) for index, run in enumerate(runs) if (said := partial_end(run)) is not None)


@dataclass(frozen=True)
class FileWork:
    """Something a caller wants made of some of a campaign's files by the worker that scans each, so
    that this process never reads a file for it (the run catalogue: the rows of files it does not hold
    yet, ``catalogue.hooks.CatalogueWriter.file_rows``).

    ``wanted`` runs here, once, before the scan, and picks the files; ``make`` runs in the worker right
    after a file scanned well, with the file and its SHA-256 from the scan (a module-level function: a
    pool or Dask sends it by name), and returns something small, or None; ``take`` runs here with each
    chunk's results as the chunk returns."""

    wanted: Callable[[Sequence[Path]], Collection[Path]]
    make: Callable[[Path, str], Any]
    take: Callable[[list[Any]], None]


def scan_chunk(
    paths: Sequence[Path],
    start_s: float | None,
    end_s: float | None,
    make: Callable[[Path, str], Any] | None = None,
    wanted: Collection[Path] = (),
) -> tuple[list[FileScan | SkippedFile], list[Any]]:
    """``scan_file`` of a chunk of files (one task for a worker), and ``make`` of each ``wanted`` file
    that scanned well (``FileWork``), what it made that is not None."""
    scans = [scan_file(path, start_s, end_s) for path in paths]
    made = []
    if make is not None:
        for scan in (s for s in scans if isinstance(s, FileScan) and s.path in wanted):
            if (found := make(scan.path, scan.sha256)) is not None:
                made.append(found)
    return scans, made


def scan_campaign(
    paths: Sequence[Path],
    start_s: float | None = None,
    end_s: float | None = None,
    executor: Executor | None = None,
    progress: Callable[[Path], None] | None = None,
    work: FileWork | None = None,
) -> CampaignScan:
    """Every file scanned in chunks on ``executor`` (here without one); ``progress`` after each file;
    ``work``: made of the files it wants by the workers that scan them, taken as each chunk returns."""
    chunks = scan_chunks(paths, executor)
    wanted = set(work.wanted(paths)) if work is not None else set()
    make = work.make if work is not None and wanted else None
    tasks = [(chunk, start_s, end_s, make, tuple(p for p in chunk if p in wanted)) for chunk in chunks]
    done: dict[int, list[FileScan | SkippedFile]] = {}
    for index, (scans, made) in completed(executor, scan_chunk, tasks):
        done[index] = scans
        if made and work is not None:
            work.take(made)
        for scan in scans:
            if progress is not None:
                progress(scan.path)
    found = CampaignScan([], [])
    for index in sorted(done):
        for scan in done[index]:
            (found.skipped if isinstance(scan, SkippedFile) else found.files).append(scan)  # type: ignore[arg-type]
    return found


def fit_chunk(
    groups: Sequence[tuple[GroupKey, Sequence[RunRef]]],
    model: str,
    hulls: dict[str, Hull],
    start_s: float | None,
    end_s: float | None,
    keep: bool,
) -> list[GroupRow]:
    """Read a chunk of groups' files (each once), fit each group (``fit_group``), return the rows."""
    read: dict[Path, list[DecayRun]] = {}
    rows = []
    for key, refs in groups:
        runs = [_decays(ref.path, read, start_s, end_s)[ref.index] for ref in refs]
        rows.append(GroupRow.of(fit_group(key, runs, model, hulls.get(key.hull)), keep))
    return rows


def _decays(path: Path, read: dict[Path, list[DecayRun]], start_s: float | None, end_s: float | None) -> list:
    """A file's cut decays, read once per chunk; a file that no longer reads as it did at the scan
    stops the campaign with its reason (it changed while the campaign ran)."""
    if path not in read:
        runs = read_campaign_file(path, start_s, end_s)
        if isinstance(runs, SkippedFile):
            from ..errors import TankdaqError

            raise TankdaqError(f"{runs.reason} (it changed while the campaign ran; run it again)")
        read[path] = runs
    return read[path]


def fit_campaign(
    groups: dict[GroupKey, list[RunRef]],
    model: str = AUTO,
    hulls: dict[str, Hull] | None = None,
    executor: Executor | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    keep: bool = False,
    progress: Callable[[GroupKey], None] | None = None,
    on_result: Callable[[GroupResult], None] | None = None,
) -> Iterator[GroupRow]:
    """Each group's row, yielded as its chunk completes (not in key order: sort by ``GroupRow.key``).

    ``start_s``/``end_s`` must be the scan's. ``keep`` also carries each group's whole ``GroupResult``
    (fit and runs: what the report's figures draw); without it the parent holds rows only.
    ``on_result`` is handed each group's whole ``GroupResult`` as it arrives, before its row is
    yielded (a catalogue writing fits as they come), and the result is then let go unless ``keep``.
    """
    known = hulls or {}
    tasks = []
    for chunk in fit_chunks(list(groups.items()), executor):
        chunk_hulls = {k.hull: known[k.hull] for k, _ in chunk if k.hull in known}
        tasks.append((chunk, model, chunk_hulls, start_s, end_s, keep or on_result is not None))
    for _, rows in completed(executor, fit_chunk, tasks):
        for row in rows:
            if on_result is not None and row.result is not None:
                on_result(row.result)
            if progress is not None:
                progress(row.key)
            yield row if keep else replace(row, result=None)


def fit_chunks(
    groups: list[tuple[GroupKey, list[RunRef]]], executor: Executor | None = None
) -> Iterator[list[tuple[GroupKey, list[RunRef]]]]:
    """Whole groups, gathered until a chunk holds its share of decays: ``chunk_size`` of all on a local
    pool; on a Dask cluster a share of what is left (``DASK_GUIDED``), at least one group."""
    threads = cluster_threads(executor)
    left = sum(len(refs) for _, refs in groups)
    size = chunk_size(left, executor)
    chunk: list[tuple[GroupKey, list[RunRef]]] = []
    decays = 0
    for group in groups:
        if not chunk and threads is not None:
            size = max(1, min(MAX_CHUNK_DECAYS, math.ceil(left / (DASK_GUIDED * threads))))
        chunk.append(group)
        decays += len(group[1])
        if decays >= size:
            yield chunk
            left -= decays
            chunk, decays = [], 0
    if chunk:
        yield chunk


def scan_chunks(paths: Sequence[Path], executor: Executor | None = None) -> list[list[Path]]:
    """The files cut for the scan: each alone here (progress after each); on a pool or a cluster one
    run of neighbouring files per worker, of about equal bytes (a scan costs about its file's size, and
    every task a fixed overhead: more on Dask than on a pool), at most ``MAX_CHUNK_DECAYS`` files each."""
    workers = executor_workers(executor)
    if workers is None or not paths:
        return [[path] for path in paths]
    count = min(len(paths), max(workers, math.ceil(len(paths) / MAX_CHUNK_DECAYS)))
    ends = np.cumsum([_size(path) for path in paths], dtype=float)
    cuts = np.searchsorted(ends, ends[-1] * np.arange(1, count) / count, side="right")
    chunks = [list(paths[a:b]) for a, b in zip([0, *cuts], [*cuts, len(paths)], strict=True) if b > a]
    return [
        chunk[i : i + MAX_CHUNK_DECAYS] for chunk in chunks for i in range(0, len(chunk), MAX_CHUNK_DECAYS)
    ]


def _size(path: Path) -> int:
    """A file's size in bytes; 1 where it cannot be read (its scan says why)."""
    try:
        return max(1, path.stat().st_size)
    except OSError:
        return 1


def executor_workers(executor: Executor | None) -> int | None:
    """How many tasks ``executor`` runs at once: a local pool's processes (``campaign.executors.LocalPool``),
    a Dask cluster's threads; None here, without one."""
    workers = getattr(executor, "workers", None)
    return workers if isinstance(workers, int) else cluster_threads(executor)


def cluster_threads(executor: Executor | None) -> int | None:
    """The worker threads of the Dask cluster behind ``executor`` (``campaign.executors.DaskExecutor``);
    None for a local pool or this process."""
    threads = getattr(executor, "threads", None)
    return threads if isinstance(threads, int) else None


def chunk_size(n: int, executor: Executor | None = None) -> int:
    """Decays (or files) per task of a pass over ``n``: about ``CHUNKS`` tasks on a local pool, one
    per worker thread on a Dask cluster; at most ``MAX_CHUNK_DECAYS`` each."""
    return max(1, min(MAX_CHUNK_DECAYS, math.ceil(n / (cluster_threads(executor) or CHUNKS))))


def completed(
    executor: Executor | None, function: Callable[..., T], tasks: Sequence[tuple[Any, ...]]
) -> Generator[tuple[int, T], None, None]:
    """(task index, result) of each task as it completes: all submitted at once (their arguments are
    paths and labels, small), in this process in order without an executor; on a Dask cluster by its
    own ``completed`` (``campaign.executors.DaskExecutor``: a pass in one message)."""
    if executor is None:
        for index, arguments in enumerate(tasks):
            yield index, function(*arguments)
        return
    if isinstance(executor, DaskExecutor):
        yield from executor.completed(function, tasks)
        return
    futures = {executor.submit(function, *arguments): i for i, arguments in enumerate(tasks)}
    try:
        for future in as_completed(futures):
            yield futures.pop(future), future.result()
    finally:  # a failed task or a consumer that stopped early: what has not started never will
        for future in futures:
            future.cancel()
