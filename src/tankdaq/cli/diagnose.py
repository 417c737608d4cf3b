"""``tankdaq diagnose``: find what a decay model is missing, add it, and show the gap shrink."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from types import ModuleType
from typing import Annotated, Any, get_args

import typer

from .. import validation
from ..errors import InputError
from ..records import DecayRun
from .app import (
    TerminalProgress,
    app,
    build_kernels_shown,
    checked,
    draft_option,
    err_console,
    handles_errors,
    progress_bar,
    say,
    warn_truncated,
)
from .identify import (
    AngleColumn,
    AngleUnit,
    CatalogueOption,
    EndS,
    KeepAll,
    RateColumn,
    RunsQuery,
    SkipHalfCycles,
    StartS,
    TimeColumn,
    TimeUnit,
    load_runs,
)

DEFAULT_BASELINE = "b1,c1"


def for_simulation(option: Any, flag: str) -> Any:
    """``identify``'s CSV option declared again for the simulation's file: the same help under its own
    flag, default None (= as the measured files are read)."""
    info = copy.copy(get_args(option)[1])
    info.default = flag  # under Annotated the first argument of typer.Option is the flag
    info.help = f"{info.help.rstrip('.')}, of the simulation (default: as the measured)."
    return info


SimTimeColumn = Annotated[str | None, for_simulation(TimeColumn, "--sim-time-col")]
SimAngleColumn = Annotated[str | None, for_simulation(AngleColumn, "--sim-angle-col")]
SimRateColumn = Annotated[str | None, for_simulation(RateColumn, "--sim-rate-col")]
SimAngleUnit = Annotated[str | None, for_simulation(AngleUnit, "--sim-angle-unit")]


@app.command("diagnose")
@handles_errors
def diagnose_command(
    inputs: Annotated[
        list[Path] | None,
        typer.Argument(
            callback=checked(validation.input_file),
            help="Decay recordings (.mcap) or CSV files, one decay each (or --runs).",
        ),
    ] = None,
    axis: str = typer.Option("roll", "--axis", help="roll or pitch."),
    baseline: str = typer.Option(
        None,
        "--baseline",
        help=f"Baseline terms ({DEFAULT_BASELINE}, the default) or an alias (ittc-linear).",
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
    simulation: list[str] = typer.Option(
        None,
        "--simulation",
        help="Compare with a simulation: a CSV or MCAP file (repeatable), hull (--hull, --draft), or ikeda.",
    ),
    sim_time_col: SimTimeColumn = None,
    sim_angle_col: SimAngleColumn = None,
    sim_rate_col: SimRateColumn = None,
    sim_angle_unit: SimAngleUnit = None,
    hull: str = typer.Option(
        None, "--hull", help="Hull config: --simulation hull, and the correction in SI."
    ),
    draft: float = draft_option(help="Draft with --hull."),
    runs_query: RunsQuery = None,
    catalogue: CatalogueOption = None,
) -> None:
    """Fit a baseline, find where it disagrees with the decays, name and add the missing effects.

    With --simulation: compare a simulation with the decays, name what it misses, add it, show the gap shrink.
    """
    from ..api.identification import Reading
    from ..api.workflows import diagnose
    from ..catalogue.hooks import CatalogueWriter
    from ..catalogue.query import inputs_or_query
    from ..catalogue.writing import fit_of_estimator, run_paths
    from ..diagnose import report as report_module

    if axis not in ("roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
    if max_steps < 0:
        raise InputError(f"--max-steps must be 0 or more, not {max_steps}")
    if simulation and baseline is not None:
        raise InputError("--baseline does not apply with --simulation: the simulation is the baseline")
    if hull is not None and not simulation:
        raise InputError("--hull applies with --simulation (the hull's model, and the correction in SI)")
    writer = CatalogueWriter.from_option(catalogue, say)
    inputs = inputs_or_query(inputs, runs_query, catalogue)
    if simulation:
        runs = load_runs(
            inputs, axis, time_col, angle_col, rate_col, angle_unit, keep_all, skip_half_cycles, start, end,
            time_unit,
        )  # fmt: skip
        columns = (sim_time_col or time_col, sim_angle_col or angle_col, sim_rate_col or rate_col)
        sim_read = (*columns, sim_angle_unit or angle_unit)
        compare_with_simulation(runs, simulation, sim_read, hull, draft, max_steps, as_json, report, rrd)
        return
    reading = Reading(
        axis, time_col, angle_col, rate_col, angle_unit, time_unit, keep_all, skip_half_cycles, start, end
    )
    build_kernels_shown()
    found = diagnose(
        inputs, baseline=baseline or DEFAULT_BASELINE, max_steps=max_steps, reading=reading,
        progress=TerminalProgress(),
    )  # fmt: skip
    final, runs = found.diagnoser.final_.estimator, found.diagnoser.runs_  # onto the recordings' rows
    with writer:
        writer.add_fit(run_paths(runs), fit_of_estimator("diagnose", final, runs, final.warnings_))
    tell(report_module, found.diagnoser, report, rrd, as_json, found.truncated_files)


def compare_with_simulation(
    runs: list[DecayRun],
    sources: list[str],
    sim_read: tuple[str, str, str, str | None],
    hull_name: str | None,
    draft: float,
    max_steps: int,
    as_json: bool,
    report: Path | None,
    rrd: Path | None,
) -> None:
    """``diagnose --simulation``: the simulation resolved and checked, compared, and told."""
    from ..config import load_hull
    from ..diagnose import sim_report
    from ..diagnose.compare import CANDIDATES, SimulationComparison
    from ..diagnose.simulation import SeriesColumns, SimulationRequest, resolve_simulation
    from ..ident.online import prepare_identifier

    hull = load_hull(hull_name) if hull_name else None
    axis = runs[0].axis if runs else "roll"
    if hull is not None:
        validation.hull_draft(hull, draft, axis)
    request = SimulationRequest(tuple(runs), axis, hull, draft, SeriesColumns(*sim_read))
    sim = resolve_simulation(sources, request)
    truncated = warn_truncated(runs)
    build_kernels_shown()
    prepare_identifier("b1,b2,c1,c3", say)
    with progress_bar() as progress:
        task = progress.add_task("comparing", total=4 + max_steps * len(CANDIDATES))

        def advance(label: str) -> None:
            progress.update(task, advance=1, description=f"fit: {label}")

        comparison = SimulationComparison(sim, max_steps=max_steps, hull=hull, progress=advance).fit(runs)
        progress.update(task, completed=progress.tasks[0].total, description="done")
    tell(sim_report, comparison, report, rrd, as_json, truncated)


def tell(
    writer: ModuleType,
    result: Any,
    report: Path | None,
    rrd: Path | None,
    as_json: bool,
    truncated: list[str],
) -> None:
    """A diagnosis or comparison told: the report, the .rrd, then the JSON or the story (``writer`` is the
    module that words it, ``diagnose.report`` or ``diagnose.sim_report``: the same four functions)."""
    if report is not None:
        err_console.print(f"report: {writer.write_report(result, report)}", markup=False, highlight=False)
    if rrd is not None:
        writer.save_rrd(result, rrd)
        err_console.print(f"rerun recording: {rrd}", markup=False, highlight=False)
    if as_json:
        document = json.loads(writer.summary_json(result))
        typer.echo(json.dumps({**document, "truncated": bool(truncated), "truncated_files": truncated}))
    else:
        for line in writer.story(result):
            typer.echo(line)
