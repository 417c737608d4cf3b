"""``tankdaq campaign``: identify a whole test campaign by group; ``tankdaq simulate-campaign``: make one."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .. import validation
from .app import (
    DRAFT_METAVAR,
    app,
    build_kernels_shown,
    checked,
    err_console,
    fail,
    handles_errors,
    progress_bar,
    say,
)
from .identify import CatalogueOption, EndS, RunsQuery, StartS


@app.command("campaign")
@handles_errors
def campaign_command(
    inputs: Annotated[
        list[Path] | None, typer.Argument(help="Recordings (.mcap, .csv) or folders of them (or --runs).")
    ] = None,
    report: Annotated[
        Path | None,
        typer.Option(
            "--report",
            callback=checked(validation.output_dir, option="--report"),
            help="Write campaign.csv, campaign.md and PNG plots here.",
        ),
    ] = None,
    model: Annotated[
        str, typer.Option("--model", help="Terms (b1,b2,c1,c3) or an alias (docs/models.md).")
    ] = "ittc-quadratic-restoring",
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
    full_scale: Annotated[
        bool,
        typer.Option("--full-scale", help="Also report at full scale (Froude; each hull's scale_factor)."),
    ] = False,
    no_recurse: Annotated[
        bool,
        typer.Option("--no-recurse", help="Read only the given folders' own files, not their subfolders."),
    ] = False,
    runs_query: RunsQuery = None,
    catalogue: CatalogueOption = None,
) -> None:
    """Group decays by hull, axis, draft and initial angle; fit each group jointly (output error).

    CSV files name their condition like trimaran_0.9T_pitch_8deg.csv (or carry a JSON sidecar with
    hull, draft, axis, angle_deg); tankdaq recordings carry it in their metadata. The table goes to
    stdout. A file that cannot be read is skipped with one line; the exit code is then 1 (results
    written for the others). Folders are searched with their subfolders (--no-recurse: not); one line
    names every folder read.
    """
    from ..catalogue.hooks import CatalogueWriter
    from ..catalogue.query import inputs_or_query
    from ..errors import InputError
    from ..ident.campaign import find_campaign_hulls, find_recordings, markdown_table
    from ..ident.campaign_stream import fit_campaign, scan_campaign
    from ..ident.executors import campaign_executor, check_scheduler
    from ..ident.online import prepare_identifier
    from ..physics.models import resolve_model

    if executor not in ("local", "dask"):
        raise InputError(f"--executor {executor!r} not understood: use local or dask")
    if (executor == "dask") != (scheduler is not None):
        raise InputError("--executor dask needs --scheduler ADDRESS, and --scheduler needs --executor dask")
    resolve_model(model)  # a typo fails before any file is read
    if scheduler is not None:
        check_scheduler(scheduler)  # an address not understood or not answering: one line, at once
    given_hulls = find_campaign_hulls([], hulls or [])  # a bad --hull fails before any file is read
    writer = CatalogueWriter.from_option(catalogue, say)
    paths = find_recordings(inputs_or_query(inputs, runs_query, catalogue), recurse=not no_recurse)
    build_kernels_shown()
    prepare_identifier(model, say)  # the native kernels: built once, on the first run after install
    prepare = []
    if report is not None:
        from ..viz.campaign_report import load_plotting, write_report

        prepare.append(load_plotting)  # loaded before the pool forks: its workers draw the figures
    cores = validation.usable_cores()
    if jobs is not None and jobs > cores and executor == "local":
        say(f"--jobs {jobs}: this machine gives tankdaq {cores} cores; running {cores} workers")
    with (
        campaign_executor(min(jobs or cores, cores), scheduler, prepare) as pool,
        progress_bar() as progress,
    ):
        reading = progress.add_task("reading", total=len(paths))

        def advance_reading(path: Path) -> None:
            progress.update(reading, advance=1, description=f"reading {path.name}")

        # the workers read the files and return each decay's group and lines, never its samples
        scan = scan_campaign(paths, start, end, pool, advance_reading)
        groups = scan.groups()
        if not groups:  # nothing to fit: the one file's own line, or every file's and a count
            if len(scan.skipped) == 1:
                raise InputError(scan.skipped[0].reason)
            for skipped in scan.skipped:
                say(skipped.line)
            raise InputError(f"no decays read: all {len(paths)} files were skipped (listed above)")
        say(folders_line(paths))  # a subfolder's decays pooled in are named, not silent
        for line in [*(skipped.line for skipped in scan.skipped), *scan.notices]:
            say(line)  # one bad file does not stop the campaign: listed, and exit 1 at the end
        known = given_hulls | find_campaign_hulls({key.hull for key in groups} - set(given_hulls))
        fitting = progress.add_task("fitting", total=len(groups))
        streamed = fit_campaign(
            groups,
            model,
            known,
            pool,
            start,
            end,
            keep=report is not None or full_scale,  # their figures and lines need the fits
            progress=lambda key: progress.update(fitting, advance=1, description=key.label),
            # each group's fit onto its recordings' catalogue rows as it arrives, then let go
            on_result=(lambda result: writer.add_campaign([result])) if writer.enabled else None,
        )
        results = sorted(streamed, key=lambda row: row.key)  # rows only: a few kB per group
        for line in scan.truncations:
            say(line)
        for line in scan.cuts:
            err_console.print(f"cut: {line}", markup=False, highlight=False, soft_wrap=True)
        typer.echo(markdown_table(results), nl=False)
        fits = [r.result for r in results if r.result is not None]
        if full_scale:
            from ..ident.derived import campaign_full_scale

            typer.echo("\n".join(campaign_full_scale(fits)))
        for result in results:
            if result.error is not None:
                err_console.print(f"warning: {result.key.label} not fitted: {result.error}", markup=False)
        for result in results:  # a fit physics says is implausible: said here, in the table and the report
            for line in result.warnings:
                err_console.print(f"warning: {result.key.label}: {line}", markup=False, soft_wrap=True)
        if report is not None:
            written = write_report(fits, report, pool)
            err_console.print(f"wrote {len(written)} files to {report}", markup=False)
    writer.close()
    if scan.skipped:
        count = f"{len(scan.skipped)} of {len(paths)} files skipped (listed above)"
        raise fail(f"{count}; the results cover the others", 1)


def folders_line(paths: list[Path]) -> str:
    """One line naming every folder recordings were read from: a subfolder's decays pooled in are seen."""
    folders = sorted({str(path.parent) for path in paths})
    return f"read {len(paths)} recording(s) from {len(folders)} folder(s): {', '.join(folders)}"


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
    axis: Annotated[str | None, typer.Option("--axis", help="roll or pitch (overrides the plan).")] = None,
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
    from ..config import load_hull
    from ..errors import InputError
    from ..ident.campaign_synthetic import write_simulated_campaign
    from ..plans import load_campaign_plan

    matrix = load_campaign_plan(plan)
    axis = axis or matrix.axis
    if axis not in ("roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
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
