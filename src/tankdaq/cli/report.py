"""``tankdaq report``: the report a lab hands over, one self-contained HTML file and a PDF."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from ..config import validation
from .app import TerminalProgress, app, build_kernels_shown, checked, err_console, fail, handles_errors, say
from .options import (
    AngleColumn,
    AngleUnit,
    CatalogueOption,
    FullScale,
    JsonOutput,
    RateColumn,
    ReadAxis,
    RunsQuery,
    SampleRate,
    SeaTemperature,
    TimeColumn,
    TimeUnit,
    WaterTemperature,
    model_option,
)

NEVER_OVER = "A file of that name is never overwritten: the report is refused before any work."


@app.command("report")
@handles_errors
def report_command(
    inputs: Annotated[
        list[Path] | None,
        typer.Argument(
            help="Recordings (.mcap, .csv), folders or patterns ('runs/*.mcap'), or a guided session's "
            "folder (its accepted decays); or --runs.",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            callback=checked(validation.output_dir, option="--out"),
            help=f"Folder for report.html and report.pdf (created). {NEVER_OVER}",
        ),
    ] = None,
    html: Annotated[
        Path | None,
        typer.Option(
            "--html", callback=checked(validation.new_file, option="--html"), help="The HTML file's name."
        ),
    ] = None,
    pdf: Annotated[
        Path | None,
        typer.Option("--pdf", callback=checked(validation.new_file, option="--pdf"), help="The PDF's name."),
    ] = None,
    model: Annotated[str, model_option()] = "auto",
    hull: Annotated[
        str | None,
        typer.Option("--hull", help="Hull file or name for every condition [default: the recordings' hull]."),
    ] = None,
    full_scale: FullScale = False,
    water_temperature: WaterTemperature = None,
    sea_temperature: SeaTemperature = None,
    axis: ReadAxis = None,
    time_col: TimeColumn = "time_s",
    angle_col: AngleColumn = "angle_deg",
    rate_col: RateColumn = "rate_deg_s",
    angle_unit: AngleUnit = None,
    time_unit: TimeUnit = None,
    sample_rate: SampleRate = None,
    as_json: JsonOutput = False,
    runs_query: RunsQuery = None,
    catalogue: CatalogueOption = None,
) -> None:
    """Fit each condition and write the report: conditions, fits with labelled intervals, B_eq and
    Bertin's N, full scale, figures, every warning and the provenance (hull and recording hashes,
    device, firmware, software, catalogue ids, this command line). --json prints the same numbers."""
    from ..api.identification import Reading
    from ..report.make import make_report
    from ..report.provenance import masked_command

    if out is None and html is None and pdf is None and not as_json:
        raise fail("give --out FOLDER, or --html/--pdf file names (or --json for the numbers only)")
    reading = Reading(axis, time_col, angle_col, rate_col, angle_unit, time_unit, sample_rate_hz=sample_rate)
    command = masked_command(["tankdaq", *sys.argv[1:]])
    build_kernels_shown()
    report = make_report(
        inputs or None, runs=runs_query, catalogue=catalogue, out=out, html=html, pdf=pdf, model=model,
        hull=hull, full_scale=full_scale, water_temperature_c=water_temperature,
        sea_temperature_c=sea_temperature, reading=reading, command=command, progress=TerminalProgress(),
    )  # fmt: skip
    for line in report.warnings:
        err_console.print(f"warning: {line}", markup=False, soft_wrap=True)
    if report.files:
        say(f"wrote {', '.join(map(str, report.files))}")
    if as_json:
        typer.echo(report.to_json())
