"""``tankdaq diagnose``: find what a decay model is missing, add it, and show the gap shrink."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .. import validation
from ..errors import InputError
from .app import app, checked, err_console, handles_errors, progress_bar, say, warn_truncated
from .identify import (
    AngleColumn,
    AngleUnit,
    EndS,
    KeepAll,
    RateColumn,
    SkipHalfCycles,
    StartS,
    TimeColumn,
    TimeUnit,
    load_runs,
)


@app.command("diagnose")
@handles_errors
def diagnose_command(
    inputs: Annotated[
        list[Path],
        typer.Argument(
            callback=checked(validation.input_file),
            help="Decay recordings (.mcap) or CSV files, one decay each.",
        ),
    ],
    axis: str = typer.Option("roll", "--axis", help="roll or pitch."),
    baseline: str = typer.Option(
        "b1,c1", "--baseline", help="Baseline terms (b1,c1) or an alias (ittc-linear)."
    ),
    max_steps: int = typer.Option(4, "--max-steps", help="At most this many effects added."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object on stdout."),
    report: Annotated[
        Path | None,
        typer.Option(
            "--report",
            callback=checked(validation.output_dir, option="--report"),
            help="Write a Markdown report with PNG figures into DIR.",
        ),
    ] = None,
    rrd: Annotated[
        Path | None,
        typer.Option(
            "--rrd",
            callback=checked(validation.output_file, option="--rrd"),
            help="Also write the story to a rerun .rrd file for the viewer.",
        ),
    ] = None,
    time_col: TimeColumn = "time_s",
    angle_col: AngleColumn = "angle_deg",
    rate_col: RateColumn = "rate_deg_s",
    angle_unit: AngleUnit = None,
    time_unit: TimeUnit = None,
    keep_all: KeepAll = False,
    skip_half_cycles: SkipHalfCycles = 0,
    start: StartS = None,
    end: EndS = None,
) -> None:
    """Fit a baseline, find where it disagrees with the decays, name and add the missing effects."""
    from ..diagnose.effects import LIBRARY
    from ..diagnose.report import save_rrd, story, summary_json, write_report
    from ..diagnose.workflow import Diagnoser
    from ..ident.online import prepare_identifier

    if axis not in ("roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
    if max_steps < 0:
        raise InputError(f"--max-steps must be 0 or more, not {max_steps}")
    runs = load_runs(
        inputs, axis, time_col, angle_col, rate_col, angle_unit, keep_all, skip_half_cycles, start, end,
        time_unit,
    )  # fmt: skip
    truncated = warn_truncated(runs)
    prepare_identifier(baseline, say)  # the native kernels: built once, on the first run after install
    with progress_bar() as progress:
        # per step: every candidate, plus the two refits of the late-disturbance test
        task = progress.add_task("baseline", total=1 + max_steps * (len(LIBRARY) + 2))

        def advance(label: str) -> None:
            progress.update(task, advance=1, description=f"refit: {label}")

        diagnoser = Diagnoser(baseline=baseline, max_steps=max_steps, progress=advance).fit(runs)
        progress.update(task, completed=progress.tasks[0].total, description="done")
    if report is not None:
        path = write_report(diagnoser, report)
        err_console.print(f"report: {path}", markup=False, highlight=False)
    if rrd is not None:
        save_rrd(diagnoser, rrd)
        err_console.print(f"rerun recording: {rrd}", markup=False, highlight=False)
    if as_json:
        document = json.loads(summary_json(diagnoser))
        typer.echo(json.dumps({**document, "truncated": bool(truncated), "truncated_files": truncated}))
    else:
        for line in story(diagnoser):
            typer.echo(line)
