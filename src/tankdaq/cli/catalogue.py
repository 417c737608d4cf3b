"""``tankdaq catalogue index DIR`` (rows rebuilt from the files), ``catalogue check URL`` (can this PC use
it) and ``tankdaq runs`` (asked like a lab asks: filters, ``--where``, ``--compare``; a table, ``--json``
or ``--csv``)."""

from __future__ import annotations

import itertools
import json
import math
from collections import Counter
from pathlib import Path
from typing import Annotated, Any

import typer

from .app import TerminalProgress, app, catalogue_option, handles_errors, say
from .options import JsonOutput

catalogue_app = typer.Typer(
    no_args_is_help=True, help="The run catalogue: rebuild its rows from files, check a catalogue."
)
app.add_typer(catalogue_app, name="catalogue")

#: The columns the default table shows (``--json``/``--csv`` give every column).
TABLE_COLUMNS = (
    ("recorded_utc", "recorded"),
    ("hull", "hull"),
    ("draft", "draft"),
    ("axis", "axis"),
    ("release_angle_deg", "angle deg"),
    ("verdict", "verdict"),
    ("natural_period_s", "T0 s"),
    ("b_eq_5deg_per_s", "B_eq 5° 1/s"),
    ("b44_hat_5deg", "B̂44 5°"),
    ("r2_angle", "R²"),
    ("fit_model", "model"),
    ("fit_method", "method"),
    ("complete", "complete"),
    ("ended", "ended"),
    ("warnings", "warnings"),
    ("path", "file"),
)
#: The table of ``runs --fits all``: one row per fit kept.
FIT_TABLE_COLUMNS = (
    ("id", "fit"),
    ("reference", "reference"),
    ("decay_path", "file"),
    ("source", "source"),
    ("method", "method"),
    ("model", "model"),
    ("natural_period_s", "T0 s"),
    ("r2_angle", "R²"),
    ("user_name", "user"),
    ("created_utc", "made"),
)
#: The table of ``runs --exports``: one row per exported file.
EXPORT_TABLE_COLUMNS = (
    ("recorded_utc", "recorded"),
    ("hull", "hull"),
    ("draft", "draft"),
    ("axis", "axis"),
    ("angle_nominal_deg", "angle deg"),
    ("recording", "recording"),
    ("decay", "decay"),
    ("format", "format"),
    ("export", "exported file"),
)


def _open(given: str | None, reading: bool = False) -> Any:
    """The catalogue ``--catalogue`` names: to write (made or migrated as needed) or, ``reading``, to
    read only (never made, migrated or written: ``database.read_catalogue``)."""
    from ..catalogue.database import BadCatalogueQuery, open_catalogue, read_catalogue, resolve_url

    url = resolve_url(given)
    if url is None:
        raise BadCatalogueQuery("the catalogue is switched off (none): give --catalogue URL|PATH")
    return read_catalogue(url) if reading else open_catalogue(url)


@catalogue_app.command("index")
@handles_errors
def index_command(
    folder: Annotated[
        Path,
        typer.Argument(
            exists=True, file_okay=False, dir_okay=True, help="Folder of recordings (searched deep)."
        ),
    ],
    catalogue: Annotated[str | None, catalogue_option()] = None,
) -> None:
    """Add every recording (.mcap), lab CSV decay (.csv) and export (.h5, .parquet, .mat, an exported
    .csv) under FOLDER and its sessions' verdicts; idempotent by SHA-256 (a file seen before is left
    alone, a moved one has its path updated)."""
    from ..catalogue.database import describe
    from ..catalogue.index import index_folder

    seen = itertools.count(1)
    with _open(catalogue) as opened, TerminalProgress().task("indexing") as update:
        report = index_folder(opened, folder, lambda p: update(next(seen), description=f"indexing {p.name}"))
    for line in report.skipped:
        say(f"skipped {line}")
    for path in report.incomplete:  # catalogued, never as a whole decay: --runs leaves it out
        say(f"not complete (cut short or corrupted): {path}: `tankdaq recover {path}` makes a whole copy")
    typer.echo(f"{describe(opened.url)}: {report.line}")


@catalogue_app.command("check")
@handles_errors
def check_command(
    url: Annotated[
        str | None,
        typer.Argument(
            metavar="URL|PATH",
            help="The catalogue to check [default: TANKDAQ_CATALOGUE, else the user data folder's].",
        ),
    ] = None,
) -> None:
    """Can this PC use the catalogue? Whether it connects (why not, in one line, its password never
    shown), its schema version against this tankdaq's, and its tables' row counts; only reads.
    Exit 0: usable; 1: not."""
    from ..catalogue.check import check_catalogue
    from ..catalogue.database import CatalogueError

    found = check_catalogue(url)
    if found.reason is not None:
        raise CatalogueError(found.reason)
    for line in found.lines():
        typer.echo(line)


def _cell(value: object) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _shown(key: str, value: object) -> object:
    """What the table shows of a value: a file's name (its folder is in --json), the time to the minute."""
    if key in ("path", "recording") and isinstance(value, str):
        return Path(value).name
    if key == "exports" and value:  # the paths in --json and --csv; here how many of each format
        formats = Counter(Path(path).suffix.lstrip(".") for path in str(value).split(" | "))
        return ", ".join(f"{count} {name}" for name, count in sorted(formats.items()))
    if key == "recorded_utc" and isinstance(value, str):
        return value[:16].replace("T", " ")
    if key == "warnings" and value:  # each one in --json; never a row without its mark
        return f"{str(value).count(' | ') + 1} warning(s)"
    if key == "complete":
        return "yes" if value else "CUT"
    if key == "reference":
        return "yes" if value else ""
    return value


def _print_table(rows: list[dict[str, Any]], columns: list[tuple[str, str]]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(show_lines=False)
    for _, title in columns:
        table.add_column(title, overflow="fold")
    for row in rows:
        table.add_row(*(_cell(_shown(key, row.get(key))) for key, _ in columns))
    console = Console(soft_wrap=False)
    if not console.is_terminal:  # a pipe or a file: every column whole, not 80 characters
        console = Console(soft_wrap=False, width=240)
    console.print(table)


def _emit(
    rows: list[dict[str, Any]],
    as_json: bool,
    as_csv: bool,
    columns: list[tuple[str, str]],
    empty: list[str] | None = None,
) -> None:
    """``rows`` as JSON, CSV or a table; ``empty``: the CSV header of a result without a row."""
    if as_json:
        clean = [
            {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in r.items()} for r in rows
        ]
        typer.echo(json.dumps(clean, indent=1, default=str))
    elif as_csv:
        import csv
        import sys

        names = list(dict.fromkeys(k for row in rows for k in row)) or (empty or [])
        writer = csv.DictWriter(sys.stdout, fieldnames=names, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    else:
        _print_table(rows, columns)


@app.command("runs")
@handles_errors
def runs_command(
    hull: Annotated[str | None, typer.Option("--hull", help="Hull name.")] = None,
    draft: Annotated[str | None, typer.Option("--draft", metavar="0.9T|T|1.1T", help="Draft.")] = None,
    axis: Annotated[str | None, typer.Option("--axis", help="roll or pitch.")] = None,
    since: Annotated[
        str | None,
        typer.Option(
            "--since",
            metavar="DATE",
            help="From 2026, 2026-03, 2026-03-15 or 2026-03-15 14:30, in UTC (a zone such as +01:00, or "
            "`local` for this PC's time, after a time).",
        ),
    ] = None,
    verdict: Annotated[
        str | None,
        typer.Option("--verdict", help="accepted, rejected or any [default: every decay not rejected]."),
    ] = None,
    where: Annotated[
        str | None,
        typer.Option(
            "--where", metavar="EXPR", help='e.g. "r2 >= 0.99 and firmware ~ 1.8" (docs/catalogue.md).'
        ),
    ] = None,
    compare: Annotated[
        tuple[str, str] | None,
        typer.Option(
            "--compare", metavar="A B", help="Two sessions (id, folder), plans or queries side by side."
        ),
    ] = None,
    exports: Annotated[
        bool,
        typer.Option(
            "--exports",
            help="One row per file `tankdaq export` wrote of the runs listed (HDF5, CSV, Parquet, .mat): "
            "where they are.",
        ),
    ] = False,
    fits: Annotated[
        str,
        typer.Option(
            "--fits",
            metavar="reference|all",
            help="reference: each decay's reference fit (the lab's number); all: one row per fit kept "
            "of the decays listed (with its id for --set-reference).",
        ),
    ] = "reference",
    set_reference: Annotated[
        int | None,
        typer.Option(
            "--set-reference",
            metavar="FIT_ID",
            help="Make this fit (an id of --fits all) its decay's reference fit; says what it replaced.",
        ),
    ] = None,
    as_json: JsonOutput = False,
    as_csv: Annotated[bool, typer.Option("--csv", help="CSV on stdout.")] = False,
    catalogue: Annotated[str | None, catalogue_option()] = None,
) -> None:
    """List catalogued decays (one row each: the reference fit's numbers, model and method, how the decay
    ended, the paths of its exports), every fit kept (--fits all), their exported files (--exports), or
    compare two campaigns per condition (decays that ended whole)."""
    from ..catalogue.comparison import compare as compare_rows
    from ..catalogue.comparison import selection
    from ..catalogue.query import (
        RunQuery,
        absent_values,
        empty_columns,
        export_listing,
        flat,
        select_rows,
    )
    from ..errors import InputError

    if as_json and as_csv:
        raise InputError("--json and --csv: give one")
    if exports and compare is not None:
        raise InputError("--exports and --compare: give one")
    if set_reference is not None:
        _set_reference(set_reference, catalogue)
        return
    if fits not in ("reference", "all"):
        raise InputError(f"--fits {fits!r}: give reference or all")
    equal = {k: v for k, v in {"hull": hull, "draft": draft, "axis": axis, "verdict": verdict}.items() if v}
    query = RunQuery(equal, since, None, where)
    query.conditions()  # a bad filter is one line before the catalogue opens
    for line in query.notes():  # a zone or local time converted to UTC
        say(line)
    with _open(catalogue, reading=True) as opened:
        if compare is not None:
            table = compare_rows(selection(opened, compare[0]), selection(opened, compare[1]))
            _emit(table, as_json, as_csv, [(k, k) for k in (table[0] if table else {})])
            return
        found = select_rows(opened, query, with_exports=True)
        for line in absent_values(opened, query) if not found else []:
            say(line)
        if fits == "all":
            _list_fits(opened, found, as_json, as_csv)
            return
    if exports:
        listing = export_listing(found)
        if not as_json and not as_csv:
            say(f"{len(listing)} exported file(s) of {len(found)} run(s)")
        _emit(listing, as_json, as_csv, list(EXPORT_TABLE_COLUMNS), empty_columns(exports=True))
        return
    rows = [flat(row) for row in found]
    if not as_json and not as_csv:
        say(f"{len(rows)} run(s)")
    shown = [("checks", "reason")] if any(row["checks"] for row in rows) else []  # why rejected, flagged
    shown += [("exports", "exports")] if any(row["exports"] for row in rows) else []
    _emit(rows, as_json, as_csv, [*TABLE_COLUMNS[:-1], *shown, TABLE_COLUMNS[-1]], empty_columns())


def _set_reference(fit_id: int, given: str | None) -> None:
    """``runs --set-reference FIT_ID``: the lab's choice of a decay's number (a write)."""
    from ..catalogue.fits import set_reference

    say(set_reference(fit_id, given))


def _list_fits(opened: Any, found: list[dict[str, Any]], as_json: bool, as_csv: bool) -> None:
    """``runs --fits all``: every fit kept of the decays ``found``, oldest first."""
    from ..catalogue.query import every_fit

    listed = every_fit(opened, found)
    if not as_json and not as_csv:
        say(f"{len(listed)} fit(s) of {len(found)} run(s)")
    _emit(listed, as_json, as_csv, list(FIT_TABLE_COLUMNS))
