"""``tankdaq.campaign``: a test campaign fitted group by group; ``tankdaq campaign`` is this call, and so is
the guided session's report (``session.report``).

The campaign streams (``campaign.stream``): the workers read the files and send back each decay's
group, then read them again a chunk of groups at a time, fit each group and send back its table row. The
caller holds the rows (a few kB per group), never the recordings, unless the fits are asked for
(``keep_fits``, or a report or full-scale results, which draw them). The workers are a process pool
(``jobs``) or a Dask cluster (``executor="dask"``, ``scheduler``); the numbers are the same.
"""

from __future__ import annotations

import html
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import validation
from ..errors import InputError
from . import arguments
from .identification import drop_read_twice, to_json, water_settings
from .progress import Kept, Progress

if TYPE_CHECKING:
    from concurrent.futures import Executor

    import pandas as pd

    from ..campaign.groups import GroupKey, GroupResult, GroupRow
    from ..campaign.stream import CampaignScan, FileWork, RunRef
    from ..config.hulls import Hull
    from ..ident.imo_table import ImoTable


@dataclass(frozen=True, eq=False)  # holds DataFrames or fits: compared by identity
class Campaign:
    """What ``campaign`` found. ``rows`` are campaign.csv's rows (``campaign.groups.GroupRow``, in group
    order) and ``table`` the same as a DataFrame; ``results`` the groups' fits and decays
    (``campaign.groups.GroupResult``) when they were kept (``keep_fits``, a report or ``full_scale``), else
    empty; ``files`` the recordings read; ``skipped`` the files that could not be read (one line each:
    the campaign went on without them); ``notices`` the lines the reading had for the user; ``cuts``
    where each decay's free part was cut, and why; ``full_scale`` the Froude lines (``full_scale=True``);
    ``report_files`` what ``report=`` wrote.

    >>> result = tankdaq.campaign("recordings/campaign")  # doctest: +SKIP
    >>> result.table[["hull", "draft", "angle_deg", "b_eq_per_s", "b44_hat"]]  # doctest: +SKIP
    >>> result.warnings  # failed fits and what physics says is implausible  # doctest: +SKIP
    """

    rows: list[GroupRow]
    results: list[GroupResult]
    files: list[Path]
    skipped: list[str]
    notices: list[str]
    cuts: list[str]
    full_scale: list[str]
    report_files: list[Path]

    @property
    def table(self) -> pd.DataFrame:
        """One row per group: coefficients per unit inertia and their std, period, B_eq, B̂44, R²."""
        import pandas as pd

        from ..ident.interval_labels import FIT_STD

        table = pd.DataFrame([row.row for row in self.rows])
        table.attrs["warnings"] = self.warnings  # an implausible result is never shown without them
        table.attrs["intervals"] = {
            column: FIT_STD.text for column in table.columns if column.endswith("_std")
        }
        return table

    @cached_property
    def imo(self) -> list[ImoTable]:
        """Bertin's N against mean amplitude at 10, 15, 20 and 25 deg per hull, axis and draft, from the
        decays at its initial angles, with what they do not reach (``ident.imo_table``)."""
        from ..ident.imo_table import imo_tables

        return imo_tables(row.cover for row in self.rows if row.cover is not None)

    @property
    def imo_table(self) -> pd.DataFrame:
        """``imo`` as one DataFrame (``imo_frame``)."""
        return imo_frame(self.imo)

    @property
    def warnings(self) -> list[str]:
        """Every group not fitted and every implausibility, one line each (``--json``'s ``warnings``)."""
        failed = [f"{row.key.label} not fitted: {row.error}" for row in self.rows if row.error is not None]
        return failed + [f"{row.key.label}: {line}" for row in self.rows for line in row.warnings]

    @property
    def document(self) -> dict[str, Any]:
        """The object ``tankdaq campaign --json`` prints: ``groups`` (the table's rows), ``warnings``,
        ``skipped``, ``cuts`` and, with ``full_scale``, its lines."""
        from ..ident.interval_labels import FIT_STD

        document = {
            "groups": [row.row for row in self.rows],
            "imo": [table.as_dict() for table in self.imo],
            "intervals": {"groups: <column>_std": FIT_STD.text, "imo: bertin_n_std": "each row's interval"},
            "budgets": [
                {"group": row.key.label, "budget": list(row.budget)} for row in self.rows if row.budget
            ],
            "warnings": self.warnings,
            "skipped": self.skipped,
            "cuts": self.cuts,
        }
        return document | ({"full_scale": self.full_scale} if self.full_scale else {})

    def to_json(self) -> str:
        """The text ``tankdaq campaign --json`` prints (NaN and infinities as null)."""
        return to_json(self.document)

    def text(self) -> str:
        """The Markdown table ``tankdaq campaign`` prints (with each group's period and B_eq/I and their
        expanded uncertainty; the whole budgets: ``budget``), then the IMO tables and the full-scale
        lines."""
        from ..campaign.groups import markdown_table
        from ..ident.imo_table import imo_markdown

        return (
            markdown_table(self.rows)
            + imo_markdown(self.imo)
            + "".join(f"{line}\n" for line in self.full_scale)
        )

    @property
    def budget(self) -> pd.DataFrame:
        """Each group's uncertainty budget, Type A from its repeats: one row per group, quantity and
        source (the columns of ``Identification.budget`` plus the group's ``condition``)."""
        from .identification import budget_table

        return budget_table([(row.key.label, row.budget) for row in self.rows])

    def _repr_html_(self) -> str:
        lines = "".join(f"<li>{html.escape(line)}</li>" for line in [*self.skipped, *self.warnings])
        return (f"<ul>{lines}</ul>" if lines else "") + self.table.to_html(index=False)


def imo_frame(tables: Sequence[ImoTable]) -> pd.DataFrame:
    """IMO tables (``ident.imo_table.ImoTable``) as one DataFrame: a row per hull, axis, draft and asked
    amplitude (N in 1/deg, its ``bertin_n_std`` labelled per row in ``interval``); ``attrs["missing"]``
    says per table which amplitudes the decays do not reach and which initial angles would."""
    import pandas as pd

    frame = pd.DataFrame([record for table in tables for record in table.records()])
    frame.attrs["missing"] = [f"{t.label}: {t.missing_line()}" for t in tables if t.missing]
    return frame


def campaign(
    inputs: str | Path | Sequence[str | Path],
    model: str = "auto",
    *,
    hulls: Sequence[str | Path] = (),
    start_s: float | None = None,
    end_s: float | None = None,
    recurse: bool = True,
    jobs: int = 1,
    executor: str = "local",
    scheduler: str | None = None,
    report: str | Path | None = None,
    full_scale: bool = False,
    water_temperature_c: float | None = None,
    sea_temperature_c: float | None = None,
    keep_fits: bool = False,
    include_partial: bool = False,
    on_result: Callable[[GroupResult], None] | None = None,
    file_work: FileWork | None = None,
    progress: Progress | None = None,
) -> Campaign:
    """Identify a test campaign: every recording or CSV in ``inputs`` (files or folders, with their
    subfolders unless ``recurse=False``) grouped by hull, axis, draft and initial angle, each group fitted
    jointly by output error (``model``: terms or an alias). ``hulls`` (names or .toml) give dimensional
    results and B̂44 (else each group's hull is looked up by name); ``start_s``/``end_s`` cut each free
    decay as ``identify`` does. ``jobs`` worker processes (at most the cores), or ``executor="dask"``
    with a ``scheduler`` address. ``report`` a folder for campaign.csv, campaign.md and the figures;
    ``full_scale`` the ship's period and damping by Froude and friction-corrected (the tank's and the
    sea's ``water_temperature_c``, ``sea_temperature_c`` in degC, as ``identify``). ``on_result`` is
    handed each group's whole fit as it arrives (the run catalogue writes it), which is then let go
    unless ``keep_fits``; a decay its recording holds only part of (stopped, the device gone, cut) is
    left out with a line unless ``include_partial``;
    ``file_work`` is made of the files it wants by the workers that read them (the run catalogue: the
    rows of files it does not hold, ``campaign.stream.FileWork``). A file that cannot be read is
    skipped with its line in ``skipped``; bad input raises ``tankdaq.errors.InputError`` before any file
    is read.

    >>> result = tankdaq.campaign("recordings/campaign", hulls=["trimaran"], jobs=2)  # doctest: +SKIP
    >>> result.table[["hull", "draft", "angle_deg", "b_eq_per_s"]]  # doctest: +SKIP
    """
    from ..campaign.executors import campaign_executor
    from ..campaign.groups import REPORT_TABLES, find_campaign_hulls, find_recordings
    from ..campaign.stream import FileWork
    from ..ident.full_scale import campaign_full_scale
    from ..live.preparation import prepare_identifier

    inputs, hulls, start_s, end_s = _arguments(inputs, hulls, start_s, end_s)
    model = arguments.model(model)
    recurse, full_scale = arguments.flag(recurse, "recurse"), arguments.flag(full_scale, "full_scale")
    water = water_settings(water_temperature_c, sea_temperature_c)
    keep_fits = arguments.flag(keep_fits, "keep_fits")
    include_partial = arguments.flag(include_partial, "include_partial")
    jobs = arguments.whole(jobs, "jobs", 1, 4096)
    executor = arguments.text(executor, "executor", "'local' or 'dask'")
    scheduler = arguments.optional_text(scheduler, "scheduler", "a Dask scheduler's address or None")
    report = arguments.optional_path(report, "report", "a folder (str or pathlib.Path) or None")
    on_result = arguments.callback(on_result, "on_result")
    file_work = arguments.optional_instance(file_work, "file_work", FileWork, "a campaign.stream.FileWork")
    kept = Kept(arguments.progress(progress))
    workers = _check_campaign(model, jobs, executor, scheduler)
    folder = validation.report_dir(Path(report), REPORT_TABLES, "report") if report is not None else None
    given_hulls = find_campaign_hulls([], hulls)  # a bad hull: before any file
    paths = find_recordings(inputs, recurse=recurse)
    prepare_identifier(model, kept.line)  # the native kernels: built once, on the first run
    prepare = []
    if folder is not None:
        from ..viz.campaign_report import load_plotting, write_report

        prepare.append(load_plotting)  # loaded before a pool forks: its workers draw the figures
    with campaign_executor(workers, scheduler, prepare) as pool:
        scan = _scan(paths, (start_s, end_s), pool, kept, file_work)
        groups = _whole_groups(scan, include_partial, kept)
        known = given_hulls | find_campaign_hulls({key.hull for key in groups} - set(given_hulls))
        keep = keep_fits or folder is not None or full_scale  # their figures and lines draw the fits
        rows = _fit(groups, model, known, pool, (start_s, end_s), keep, on_result, kept)
        for line in scan.truncations:
            kept.line(line)
        results = [row.result for row in rows if row.result is not None]
        written = write_report(results, folder, pool) if folder is not None else []
    scaled = campaign_full_scale(results, water) if full_scale else []
    if not keep_fits:  # the fits were kept for the report and the full-scale lines only
        results = []
        rows = [replace(row, result=None) for row in rows]
    skipped = [skipped.line for skipped in scan.skipped]
    return Campaign(rows, results, paths, skipped, kept.lines, scan.cuts, scaled, list(written))


def _arguments(
    inputs: object, hulls: object, start_s: object, end_s: object
) -> tuple[list[Path], list[str], float | None, float | None]:
    """``campaign``'s files, hulls and cut, checked by name (``api.arguments``): one path or hull given
    alone is one, never its characters."""
    start = arguments.optional_number(start_s, "start_s", 0.0, unit="seconds from the release")
    end = arguments.optional_number(end_s, "end_s", 0.0, unit="seconds from the release")
    if start is not None and end is not None and end <= start:
        raise InputError(f"end_s: give a time after start_s ({start:g} s), not {end:g} s")
    files = arguments.paths(inputs, "inputs", "a file or folder path, or a list of them")
    return (
        files,
        arguments.names(hulls, "hulls", "a hull's name or .toml path, or a list of them"),
        start,
        end,
    )


def _check_campaign(model: str, jobs: int, executor: str, scheduler: str | None) -> int:
    """The settings checked before any file is read; the worker processes to start (1: none)."""
    from ..campaign.executors import check_scheduler
    from ..physics.models import resolve_model

    resolve_model(model)  # a typo fails before any file is read
    validation.campaign_executor(executor, scheduler, option="executor", scheduler_option="scheduler")
    if scheduler is not None:
        check_scheduler(scheduler)  # an address not understood or not answering: one line, at once
    return min(jobs, validation.usable_cores())


def _scan(
    paths: list[Path],
    window: tuple[float | None, float | None],
    pool: Executor | None,
    kept: Kept,
    work: FileWork | None,
) -> CampaignScan:
    """Every file scanned by the workers (each decay's group and lines, never its samples); the folders
    read, the files skipped and what the reading decided said in one line each. A campaign of which no
    file reads is refused: the one file's reason, or every file's line and a count."""
    from ..campaign.stream import scan_campaign

    with kept.task("reading", len(paths)) as advance:
        count = iter(range(1, len(paths) + 1))
        scan = scan_campaign(
            paths,
            *window,
            pool,
            lambda path: advance(next(count), description=f"reading {path.name}"),
            work,
        )
    read = [found.path for found in scan.files]  # a copy or an export of another: its decays once
    digests = {found.path: found.sha256 for found in scan.files}
    kept_paths = set(drop_read_twice(read, kept, digests, {found.path: found.origin for found in scan.files}))
    scan.files = [found for found in scan.files if found.path in kept_paths]
    if not scan.decays:
        if len(scan.skipped) == 1:
            raise InputError(scan.skipped[0].reason)
        for skipped in scan.skipped:
            kept.line(skipped.line)
        raise InputError(f"no decays read: all {len(paths)} files were skipped (listed above)")
    kept.line(folders_line(paths))  # a subfolder's decays pooled in are named, not silent
    for line in [*(skipped.line for skipped in scan.skipped), *scan.notices]:
        kept.line(line)  # one bad file does not stop the campaign: listed
    return scan


def _whole_groups(scan: CampaignScan, include_partial: bool, kept: Kept) -> dict[GroupKey, list[RunRef]]:
    """The scan's groups, without the decays not recorded whole unless ``include_partial`` (each said
    in a line); a campaign left with nothing to fit is refused in one line."""
    for line in scan.partial_lines(include_partial):
        kept.line(line)
    groups = scan.groups(include_partial)
    if not groups:
        raise InputError(
            "every decay read was recorded only in part (listed above): --include-partial "
            "(include_partial=True) fits them anyway"
        )
    return groups


def _fit(
    groups: dict[GroupKey, list[RunRef]],
    model: str,
    hulls: dict[str, Hull],
    pool: Executor | None,
    window: tuple[float | None, float | None],
    keep: bool,
    on_result: Callable[[GroupResult], None] | None,
    kept: Kept,
) -> list[GroupRow]:
    """Each group fitted by the workers; its row kept (with its fit when ``keep``), in group order."""
    from ..campaign.stream import fit_campaign

    with kept.task("fitting", len(groups)) as advance:
        count = iter(range(1, len(groups) + 1))
        streamed = fit_campaign(
            groups,
            model,
            hulls,
            pool,
            *window,
            keep=keep,
            progress=lambda key: advance(next(count), description=key.label),
            on_result=on_result,
        )
        rows = sorted(streamed, key=lambda row: row.key)  # rows only unless keep: a few kB per group
    for row in rows:  # which model each group was fitted with, and why: as identify says it
        if row.error is None:
            kept.line(f"{row.key.label}: {row.row['model_reason']}")
    return rows


def folders_line(paths: list[Path]) -> str:
    """One line naming every folder recordings were read from: a subfolder's decays pooled in are seen."""
    folders = sorted({str(path.parent) for path in paths})
    return f"read {len(paths)} recording(s) from {len(folders)} folder(s): {', '.join(folders)}"
