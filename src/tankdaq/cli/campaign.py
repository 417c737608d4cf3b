"""``tankdaq campaign``: identify a whole test campaign by group; ``tankdaq simulate-campaign``: make one."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..config import validation
from .app import (
    DRAFT_METAVAR,
    TerminalProgress,
    app,
    build_kernels_shown,
    checked,
    err_console,
    fail,
    handles_errors,
    say,
    say_cuts,
)
from .options import (
    CatalogueOption,
    EndS,
    FullScale,
    JsonOutput,
    RunsQuery,
    SeaTemperature,
    StartS,
    WaterTemperature,
    model_option,
    report_option,
)


@app.command("campaign")
@handles_errors
def campaign_command(
    inputs: Annotated[
        list[Path] | None, typer.Argument(help="Recordings (.mcap, .csv) or folders of them (or --runs).")
    ] = None,
    report: Annotated[
        Path | None, report_option("Write campaign.csv, campaign.md and PNG plots here.")
    ] = None,
    model: Annotated[str, model_option()] = "auto",
    hulls: Annotated[
        list[str] | None,
        typer.Option("--hull", help="Hull files or names for dimensional results (repeat; else by name)."),
    ] = None,
    start: StartS = None,
    end: EndS = None,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs",
            min=1,
            help="Worker processes for reading, fits and plots [default and at most: the cores].",
        ),
    ] = None,
    executor: Annotated[
        str, typer.Option("--executor", help="local (a process pool) or dask (needs --scheduler).")
    ] = "local",
    scheduler: Annotated[
        str | None,
        typer.Option("--scheduler", help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (tankdaq[dask])."),
    ] = None,
    full_scale: FullScale = False,
    water_temperature: WaterTemperature = None,
    sea_temperature: SeaTemperature = None,
    no_recurse: Annotated[
        bool,
        typer.Option("--no-recurse", help="Read only the given folders' own files, not their subfolders."),
    ] = False,
    include_partial: Annotated[
        bool,
        typer.Option(
            "--include-partial",
            help="Fit decays recorded only in part too (stopped, the device gone, cut); left out by default.",
        ),
    ] = False,
    as_json: JsonOutput = False,
    runs_query: RunsQuery = None,
    catalogue: CatalogueOption = None,
) -> None:
    """Group decays by hull, axis, draft and initial angle; fit each group jointly (output error).

    CSV files name their condition like trimaran_0.9T_pitch_8deg.csv (or carry a JSON sidecar with
    hull, draft, axis, angle_deg); tankdaq recordings carry it in their metadata. The table (or with
    --json one JSON object) goes to stdout. A file that cannot be read is skipped with one line; the exit
    code is then 1 (results written for the others). Folders are searched with their subfolders
    (--no-recurse: not); one line names every folder read.
    """
    from ..api.campaigns import campaign
    from ..catalogue.hooks import CatalogueWriter
    from ..catalogue.query import asks_ended, inputs_or_query

    validation.campaign_executor(executor, scheduler)  # the pair checked before anything is opened
    writer = CatalogueWriter.from_option(catalogue, say)
    inputs = inputs_or_query(inputs, runs_query, catalogue)
    cores = validation.usable_cores()
    if jobs is not None and jobs > cores and executor == "local":
        say(f"--jobs {jobs}: this machine gives tankdaq {cores} cores; running {cores} workers")
    build_kernels_shown()
    catalogued = (lambda fit: writer.add_campaign([fit])) if writer.enabled else None
    rows = writer.file_rows() if writer.enabled else None  # a new file's row: made where it is read
    with writer:  # each group's fit onto its recordings' catalogue rows as it arrives, then let go
        result = campaign(
            inputs, model, hulls=hulls or [], start_s=start, end_s=end, recurse=not no_recurse,
            jobs=min(jobs or cores, cores), executor=executor, scheduler=scheduler, report=report,
            full_scale=full_scale, water_temperature_c=water_temperature,
            sea_temperature_c=sea_temperature, include_partial=include_partial or asks_ended(runs_query),
            on_result=catalogued, file_work=rows, progress=TerminalProgress(),
        )  # fmt: skip
    say_cuts(result.cuts)
    typer.echo(result.to_json() if as_json else result.text(), nl=as_json)
    for line in result.warnings:  # a fit physics says is implausible: said here, in the table and the report
        err_console.print(f"warning: {line}", markup=False, soft_wrap=True)
    if report is not None:
        err_console.print(f"wrote {len(result.report_files)} files to {report}", markup=False)
    if result.skipped:
        count = f"{len(result.skipped)} of {len(result.files)} files skipped (listed above)"
        raise fail(f"{count}; the results cover the others", 1)


@app.command("simulate-campaign")
@handles_errors
def simulate_campaign_command(
    folder: Annotated[
        Path,
        typer.Argument(
            callback=checked(validation.output_dir, option="FOLDER"),
            help="Folder for the simulated recordings (created).",
        ),
    ],
    plan: Annotated[
        str, typer.Option("--plan", help="Test matrix from configs/campaigns (hulls, axis, drafts, angles).")
    ] = "seed000-trimaran-catamaran-pitch",
    hulls: Annotated[
        list[str] | None, typer.Option("--hull", help="Hull configs (repeat; overrides the plan).")
    ] = None,
    axis: Annotated[
        str | None,
        typer.Option(
            "--axis", callback=checked(validation.decay_axis), help="roll or pitch (overrides the plan)."
        ),
    ] = None,
    drafts: Annotated[
        list[str] | None,
        typer.Option(
            "--draft",
            callback=checked(validation.draft_factor, keep_input=True),
            metavar=DRAFT_METAVAR,
            help="Drafts (repeat; overrides the plan).",
        ),
    ] = None,
    angles_deg: Annotated[
        list[float] | None,
        typer.Option(
            "--angle",
            callback=checked(validation.release_angle_deg),
            help="Initial angles, deg (repeat; overrides the plan).",
        ),
    ] = None,
    file_format: Annotated[str, typer.Option("--format", help="csv or mcap.")] = "csv",
    seed: Annotated[int, typer.Option("--seed", help="Noise seed.")] = 0,
) -> None:
    """Simulate a decay campaign from configs/hulls, following a test matrix from configs/campaigns
    (default: seed 000's trimaran and catamaran pitch decays at 0.9T, T, 1.1T from 2, 4, 6, 8 deg)."""
    from ..campaign.synthetic import write_simulated_campaign
    from ..config.hulls import load_hull
    from ..config.plans import load_campaign_plan

    matrix = load_campaign_plan(plan)
    axis = axis or matrix.axis  # the plan's is checked where it is read
    draft_factors = [validation.draft_factor(d) for d in drafts or matrix.drafts]
    for hull in hulls or matrix.hulls:  # every condition is checked before the first file is written
        for draft in draft_factors:
            validation.hull_draft(load_hull(hull), draft, axis)
    written = write_simulated_campaign(
        folder,
        hulls or matrix.hulls,
        axis,
        draft_factors,
        angles_deg or matrix.angles_deg,
        file_format,
        seed=seed,
    )
    typer.echo(f"wrote {len(written)} {file_format} recordings to {folder}")
