"""``tankdaq diagnose``: find what a decay model is missing, add it, and show the gap shrink."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Annotated, Any, get_args

import typer

from ..config import validation
from ..errors import InputError
from .app import (
    TerminalProgress,
    app,
    build_kernels_shown,
    checked,
    draft_option,
    err_console,
    handles_errors,
    say,
)
from .options import (
    AngleColumn,
    AngleUnit,
    CatalogueOption,
    DecayAxis,
    EndS,
    JsonOutput,
    KeepAll,
    LogDevice,
    RateColumn,
    RunsQuery,
    SampleRate,
    SkipHalfCycles,
    SpeedColumn,
    StartS,
    TimeColumn,
    TimeUnit,
    report_option,
)

#: The baseline without --baseline (``api.diagnosis.DEFAULT_BASELINE``, named here for --help).
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
            help="Recordings (.mcap) or decay files (.csv .h5 .mat .parquet), one decay each (or --runs).",
        ),
    ] = None,
    axis: DecayAxis = "roll",
    baseline: str = typer.Option(
        None,
        "--baseline",
        help=f"Baseline terms ({DEFAULT_BASELINE}, the default) or an alias (ittc-linear).",
    ),
    max_steps: int = typer.Option(4, "--max-steps", min=0, help="At most this many effects added."),
    as_json: JsonOutput = False,
    report: Annotated[
        Path | None, report_option("Write a Markdown report with PNG figures into DIR.")
    ] = None,
    rrd: Annotated[
        Path | None,
        typer.Option(
            "--rrd",
            callback=checked(validation.new_file, option="--rrd"),
            help="Also write the story to a rerun .rrd file for the viewer.",
        ),
    ] = None,
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
    simulation: list[str] = typer.Option(
        None,
        "--simulation",
        help="Compare with a simulation: a decay file (.csv .h5 .mat .parquet .mcap), hull or ikeda "
        "(repeatable).",
    ),
    sim_time_col: SimTimeColumn = None,
    sim_angle_col: SimAngleColumn = None,
    sim_rate_col: SimRateColumn = None,
    sim_angle_unit: SimAngleUnit = None,
    hull: str = typer.Option(
        None, "--hull", help="Hull config: --simulation hull, and the correction in SI."
    ),
    draft: float = draft_option(help="Draft with --hull."),
    speed: float = typer.Option(
        None,
        "--speed",
        help="Carriage speed of the decays, m/s, for --simulation ikeda (default: the recordings' speed, "
        "else the hull's speed_m_s, else 0).",
    ),
    runs_query: RunsQuery = None,
    catalogue: CatalogueOption = None,
) -> None:
    """Fit a baseline, find where it disagrees with the decays, name and add the missing effects.

    With --simulation: compare a simulation with the decays, name what it misses, add it, show the gap shrink.
    """
    from ..api.diagnosis import diagnose
    from ..api.identification import Reading, to_json
    from ..catalogue.fits import FitSource
    from ..catalogue.hooks import CatalogueWriter
    from ..catalogue.query import inputs_or_query
    from ..catalogue.writing import fit_of_estimator, run_files

    if simulation and baseline is not None:
        raise InputError("--baseline does not apply with --simulation: the simulation is the baseline")
    if speed is not None and not simulation:
        raise InputError("--speed applies with --simulation (the speed the prediction is made at)")
    if hull is not None and not simulation:
        raise InputError("--hull applies with --simulation (the hull's model, and the correction in SI)")
    writer = CatalogueWriter.from_option(catalogue, say)
    inputs = inputs_or_query(inputs, runs_query, catalogue)
    reading = Reading(
        axis, time_col, angle_col, rate_col, angle_unit, time_unit, keep_all, skip_half_cycles, start, end,
        sample_rate, device, speed_col,
    )  # fmt: skip
    columns = (sim_time_col or time_col, sim_angle_col or angle_col, sim_rate_col or rate_col)
    sim_reading = Reading(axis, *columns, sim_angle_unit or angle_unit)
    build_kernels_shown()
    found = diagnose(
        inputs, baseline=baseline, max_steps=max_steps, reading=reading, simulation=simulation or None,
        simulation_reading=sim_reading, hull=hull, draft=draft, speed=speed, report=report,
        progress=TerminalProgress(),
    )  # fmt: skip
    warnings = getattr(found.estimator, "warnings_", [])  # the decays' final fit onto their rows
    with writer:
        writer.add_fit(
            run_files(found.runs), fit_of_estimator(FitSource.DIAGNOSE, found.estimator, found.runs, warnings)
        )
    if found.report is not None:
        err_console.print(f"report: {found.report}", markup=False, highlight=False)
    if rrd is not None:
        found.save_rrd(rrd)
        err_console.print(f"rerun recording: {rrd}", markup=False, highlight=False)
    if as_json:
        cut = found.truncated_files
        typer.echo(to_json({**found.document, "truncated": bool(cut), "truncated_files": cut}))
    else:
        for line in found.story:
            typer.echo(line)
