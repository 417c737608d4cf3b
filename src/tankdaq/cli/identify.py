"""``tankdaq identify``: damping and restoring coefficients from decay recordings or CSV files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from .. import validation
from ..records import DecayRun
from .app import (
    TerminalProgress,
    app,
    build_kernels_shown,
    catalogue_option,
    checked,
    draft_option,
    err_console,
    handles_errors,
    progress_bar,
    runs_option,
    say,
    warn_truncated,
)

if TYPE_CHECKING:
    from ..api.identification import Reading
    from ..catalogue.hooks import CatalogueWriter

# The run catalogue (identify, campaign, diagnose): where fits are written, and --runs in place of paths.
CatalogueOption = Annotated[str | None, catalogue_option()]
RunsQuery = Annotated[str | None, runs_option()]

# Options every command that reads decays shares (identify, diagnose): how to read other labs' CSV.
TimeColumn = Annotated[str, typer.Option("--time-col", help="CSV time column (s).")]
AngleColumn = Annotated[str, typer.Option("--angle-col", help="CSV angle column.")]
RateColumn = Annotated[str, typer.Option("--rate-col", help="CSV rate column (ignored when absent).")]
AngleUnit = Annotated[
    str | None,
    typer.Option("--angle-unit", help="Unit of the CSV angle and rate: deg or rad [default: from the data]."),
]
TimeUnit = Annotated[
    str | None, typer.Option("--time-unit", help="Unit of the CSV time: s or ms [default: from the data].")
]
KeepAll = Annotated[bool, typer.Option("--keep-all", help="Do not cut the CSV record at the release.")]
SkipHalfCycles = Annotated[
    int, typer.Option("--skip-half-cycles", min=0, help="Half-cycles dropped after it.")
]
# Where the free decay is taken from and to (identify, diagnose, campaign); automatic end by default.
StartS = Annotated[
    float | None, typer.Option("--start", min=0.0, help="Keep from S s after each release (default 0).")
]
EndS = Annotated[
    float | None,
    typer.Option("--end", min=0.0, help="End each free decay S s after its release (default: found)."),
]


def echo_cuts(runs: list[DecayRun]) -> None:
    """One line per run on stderr: where its free decay was cut and why."""
    from ..ident.free_decay import cut_lines

    for line in cut_lines(runs):
        err_console.print(f"cut: {line}", markup=False, highlight=False, soft_wrap=True)


def load_runs(
    inputs: list[Path],
    axis: str | None,
    time_col: str,
    angle_col: str,
    rate_col: str | None,
    angle_unit: str | None,
    keep_all: bool,
    skip_half_cycles: int,
    start_s: float | None = None,
    end_s: float | None = None,
    time_unit: str | None = None,
) -> list[DecayRun]:
    """The free decays of every input, read and cut as ``tankdaq.identify`` reads them
    (``api.identification.load_runs``); what the reading decided is said in one line each."""
    from ..api.identification import Reading
    from ..api.identification import load_runs as read_and_cut

    reading = Reading(
        axis, time_col, angle_col, rate_col, angle_unit, time_unit, keep_all, skip_half_cycles, start_s, end_s
    )
    return read_and_cut(inputs, reading, TerminalProgress())


@app.command("identify")
@handles_errors
def identify_command(
    inputs: Annotated[
        list[Path] | None,
        typer.Argument(
            callback=checked(validation.input_file),
            help="Decay recordings (.mcap) or CSV files, one decay each (or --runs).",
        ),
    ] = None,
    axis: str = typer.Option(
        None, "--axis", help="roll or pitch (default: a recording's own axis; roll for CSV)."
    ),
    model: str = typer.Option(
        "auto",
        "--model",
        help="auto (the best of a small family on held-out data), terms (b1,b2,c1,c3) or an alias "
        "(docs/models.md).",
    ),
    method: str = typer.Option("oe", "--method", help="oe (output error), ee (equation error), ..."),
    compare: bool = typer.Option(
        False, "--compare", help="Fit every seed formula and ITTC form; print the table."
    ),
    joint: bool = typer.Option(
        False, "--joint", help="Fit decays of different conditions (hull, draft, axis) together (warned)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object on stdout."),
    time_col: TimeColumn = "time_s",
    angle_col: AngleColumn = "angle_deg",
    rate_col: RateColumn = "rate_deg_s",
    angle_unit: AngleUnit = None,
    time_unit: TimeUnit = None,
    keep_all: KeepAll = False,
    skip_half_cycles: SkipHalfCycles = 0,
    start: StartS = None,
    end: EndS = None,
    bootstrap: int = typer.Option(
        0,
        "--bootstrap",
        callback=checked(validation.bootstrap_replicas),
        help=f"Moving-block bootstrap replicas for intervals (up to {validation.MAX_BOOTSTRAP_REPLICAS}).",
    ),
    repeats: bool = typer.Option(
        False, "--repeats", help="The runs are repeats: intervals from their spread (t, n-1 dof)."
    ),
    hull: str = typer.Option(None, "--hull", help="Hull config for dimensional results."),
    draft: float = draft_option(help="Draft with --hull."),
    full_scale: bool = typer.Option(
        False, "--full-scale", help="Also report at full scale (Froude; the hull's scale_factor)."
    ),
    runs_query: RunsQuery = None,
    catalogue: CatalogueOption = None,
) -> None:
    """Identify the decay equation's coefficients from free-decay records.

    Decays of different conditions (hull, draft, axis from the recordings' metadata or names) get one
    fit each unless --joint; the default model is chosen by the data (docs/models.md).
    """
    from ..api.identification import Reading, identify
    from ..catalogue.hooks import CatalogueWriter
    from ..catalogue.query import inputs_or_query

    writer = CatalogueWriter.from_option(catalogue, say)  # a --catalogue not understood: one line, now
    inputs = inputs_or_query(inputs, runs_query, catalogue)
    reading = Reading(
        axis, time_col, angle_col, rate_col, angle_unit, time_unit, keep_all, skip_half_cycles, start, end
    )
    if compare:
        _compare(inputs, reading, method, as_json)
        return
    build_kernels_shown()
    result = identify(
        inputs, model, method=method, joint=joint, hull=hull, draft=draft, full_scale=full_scale,
        bootstrap=bootstrap, repeats=repeats, reading=reading, progress=TerminalProgress(),
    )  # fmt: skip
    with writer:
        for fit in result.fits:
            if not fit.pooled:  # a fit of one condition: the rows of its recordings carry it
                _catalogue_fit(writer, "identify", fit.summary, fit.runs)
    typer.echo(result.to_json() if as_json else result.text())


def _compare(inputs: list[Path], reading: Reading, method: str, as_json: bool) -> None:
    """``--compare``: every seed formula and ITTC form fitted to the decays, the table printed."""
    from ..api.identification import load_runs, to_json, truncations
    from ..ident.comparison import compare_models, compare_text, group_models
    from ..ident.conditions import group_conditions, grouping_line
    from ..ident.estimators import make_estimator
    from ..ident.free_decay import cut_lines
    from ..ident.online import prepare_identifier
    from ..physics.models import COMPARE_MODELS, MODEL_FAMILY

    make_estimator(method, MODEL_FAMILY[0])  # an unknown method fails before any reading
    runs = load_runs(inputs, reading, TerminalProgress())
    cut = list(truncations(runs))
    warn_truncated(runs)
    groups = group_conditions(runs)
    pooled = grouping_line(groups, joint=True) if len(groups) > 1 else None
    prepare_identifier(MODEL_FAMILY[-1], say)  # the native kernels: built once, on the first run
    if pooled is not None:
        say(f"warning: {pooled}")
    with progress_bar() as progress:
        task = progress.add_task("fitting models", total=len(group_models(COMPARE_MODELS)))
        rows = compare_models(
            runs, COMPARE_MODELS, method, lambda name: progress.update(task, advance=1, description=name)
        )
    if as_json:
        document = {
            "compare": rows,
            "cuts": cut_lines(runs),
            "warnings": [pooled] if pooled else [],
            "truncated": bool(cut),
            "truncated_files": cut,
        }
        typer.echo(to_json(document))
    else:
        echo_cuts(runs)
        typer.echo(compare_text(rows))


def _catalogue_fit(writer: CatalogueWriter, source: str, summary: dict, runs: list[DecayRun]) -> None:
    """A condition's fit onto its recordings' catalogue rows."""
    from ..catalogue.writing import fit_of_summary, run_paths

    writer.add_fit(run_paths(runs), fit_of_summary(source, summary, runs))
