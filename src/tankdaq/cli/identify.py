"""``tankdaq identify``: damping and restoring coefficients from decay recordings or CSV files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ..config import validation
from .app import (
    TerminalProgress,
    app,
    build_kernels_shown,
    checked,
    draft_option,
    handles_errors,
    say,
    say_cuts,
)
from .options import (
    AngleColumn,
    AngleUnit,
    CatalogueOption,
    EndS,
    FullScale,
    JsonOutput,
    KeepAll,
    LogDevice,
    RateColumn,
    ReadAxis,
    RunsQuery,
    SampleRate,
    SeaTemperature,
    SkipHalfCycles,
    SpeedColumn,
    StartS,
    TimeColumn,
    TimeUnit,
    WaterTemperature,
    model_option,
)

if TYPE_CHECKING:
    from ..api.identification import ConditionFit, Reading
    from ..catalogue.hooks import CatalogueWriter


@app.command("identify")
@handles_errors
def identify_command(
    inputs: Annotated[
        list[Path] | None,
        typer.Argument(
            callback=checked(validation.input_file),
            help="Recordings (.mcap) or decay files (.csv .h5 .mat .parquet), one decay each (or --runs).",
        ),
    ] = None,
    axis: ReadAxis = None,
    model: Annotated[str, model_option()] = "auto",
    method: str = typer.Option("oe", "--method", help="oe (output error), ee (equation error), ..."),
    compare: bool = typer.Option(
        False, "--compare", help="Fit every seed formula and ITTC form; print the table."
    ),
    joint: bool = typer.Option(
        False, "--joint", help="Fit decays of different conditions (hull, draft, axis) together (warned)."
    ),
    as_json: JsonOutput = False,
    time_col: TimeColumn = "time_s",
    angle_col: AngleColumn = "angle_deg",
    rate_col: RateColumn = "rate_deg_s",
    angle_unit: AngleUnit = None,
    time_unit: TimeUnit = None,
    sample_rate: SampleRate = None,
    keep_all: KeepAll = False,
    skip_half_cycles: SkipHalfCycles = 0,
    start: StartS = None,
    end: EndS = None,
    device: LogDevice = None,
    speed_col: SpeedColumn = None,
    bootstrap: int = typer.Option(
        0,
        "--bootstrap",
        callback=checked(validation.bootstrap_replicas),
        help=f"Moving-block bootstrap replicas for intervals (up to {validation.MAX_BOOTSTRAP_REPLICAS}).",
    ),
    repeats: bool = typer.Option(
        False, "--repeats", help="The runs are repeats: intervals from their spread (t, n-1 dof)."
    ),
    angle_accuracy: float = typer.Option(
        None,
        "--angle-accuracy",
        metavar="DEG",
        callback=checked(validation.angle_accuracy_deg),
        help="The device's roll/pitch accuracy (deg RMS) for the uncertainty budget (default: datasheet).",
    ),
    hull: str = typer.Option(None, "--hull", help="Hull config for dimensional results."),
    draft: float = draft_option(help="Draft with --hull."),
    full_scale: FullScale = False,
    water_temperature: WaterTemperature = None,
    sea_temperature: SeaTemperature = None,
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
    from ..ident.budget_inputs import with_accuracy

    writer = CatalogueWriter.from_option(catalogue, say)  # a --catalogue not understood: one line, now
    inputs = inputs_or_query(inputs, runs_query, catalogue)
    reading = Reading(
        axis, time_col, angle_col, rate_col, angle_unit, time_unit, keep_all, skip_half_cycles, start, end,
        sample_rate, device, speed_col,
    )  # fmt: skip
    if compare:
        _compare(inputs, reading, method, as_json)
        return
    build_kernels_shown()
    result = identify(
        inputs, model, method=method, joint=joint, hull=hull, draft=draft, full_scale=full_scale,
        water_temperature_c=water_temperature, sea_temperature_c=sea_temperature, bootstrap=bootstrap,
        repeats=repeats, reading=reading, progress=TerminalProgress(),
        device=None if angle_accuracy is None else with_accuracy(angle_accuracy),
    )  # fmt: skip
    with writer:
        for fit in result.fits:
            _catalogue_fit(writer, fit)
    typer.echo(result.to_json() if as_json else result.text())


def _compare(inputs: list[Path], reading: Reading, method: str, as_json: bool) -> None:
    """``--compare``: every seed formula and ITTC form fitted to the decays (``tankdaq.compare_models``)."""
    from ..api.comparison import compare_models

    build_kernels_shown()
    found = compare_models(inputs, method=method, reading=reading, progress=TerminalProgress())
    for line in found.warnings:
        say(f"warning: {line}")
    if not as_json:
        say_cuts(found.cuts)
    typer.echo(found.to_json() if as_json else found.text())


def _catalogue_fit(writer: CatalogueWriter, fit: ConditionFit) -> None:
    """A fit onto its recordings' catalogue rows: a condition's as ``identify``; a ``--joint`` fit of
    several conditions as ``identify-joint`` (its warnings say it pooled them) on each condition's
    rows, its B̂44 at that condition's draft."""
    from ..catalogue.fits import FitSource
    from ..catalogue.writing import fit_of_summary, run_files
    from ..ident.conditions import group_conditions

    source = FitSource.IDENTIFY_JOINT if fit.pooled else FitSource.IDENTIFY
    for runs in group_conditions(fit.runs).values() if fit.pooled else [fit.runs]:
        writer.add_fit(run_files(runs), fit_of_summary(source, fit.summary.to_dict(), runs))
