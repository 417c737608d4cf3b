"""``tankdaq auv ...``: AUV diving-plane manoeuvres (seed 003): simulate, identify, sensitivity, validate."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from ..config import validation
from ..errors import InputError
from .app import app, checked, err_console, handles_errors
from .options import JsonOutput

if TYPE_CHECKING:  # the auv models compile with numba: imported by the commands that run them
    from ..auv.model import StateRecord
    from ..auv.sensitivity import SensitivityResult
    from ..auv.vehicle import Vehicle

auv_app = typer.Typer(
    no_args_is_help=True,
    help="AUV diving-plane manoeuvres (seed 003): simulate, identify, sensitivity, validate.",
)
app.add_typer(auv_app, name="auv")

DEFAULT_VEHICLE = "nps_auv2"
DEFAULT_DELTA_DEG = 15.0
DEFAULT_THETA_DEG = 10.0
METHODS = ("lssvm", "ols")
DELTA_HELP = "Stern-plane angle about trim [deg]."
THETA_HELP = "Pitch at which the plane reverses [deg]."
RECORD_VEHICLE_HELP = "Vehicle (default: the one the record carries)."


def parse_noise(text: str) -> float:
    """'none' -> 0, 'realistic' -> 1, a number -> that multiple of the realistic sensor noise."""
    named = {"none": 0.0, "realistic": 1.0}
    if text.lower() in named:
        return named[text.lower()]
    try:
        scale = float(text)
    except ValueError:
        raise InputError(
            f"--noise {text!r} not understood: use none, realistic or a factor such as 0.5"
        ) from None
    if not 0 <= scale <= 100:
        raise InputError(f"--noise {text!r}: the factor must be between 0 and 100")
    return scale


@contextmanager
def _progress(description: str) -> Iterator[Callable[[int, int], None]]:
    """A rich progress bar on stderr, advanced by the callback it yields."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
    )
    with Progress(*columns, console=err_console, transient=True) as bar:
        task = bar.add_task(description, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise InputError(f"--method {method!r} unknown; use {' or '.join(METHODS)}")


def _vehicle_for(path: Path, record: StateRecord, name: str | None) -> Vehicle:
    """The vehicle named on the command line, else the one the record carries or names."""
    from ..auv.io import read_vehicle_attachment
    from ..auv.vehicle import list_vehicles, load_vehicle

    if name:
        return load_vehicle(name)
    attached = read_vehicle_attachment(path)
    if attached is not None:
        return attached
    if record.meta.get("vehicle"):
        return load_vehicle(record.meta["vehicle"])
    known = ", ".join(list_vehicles())
    raise InputError(f"{path} does not say which vehicle it is; give --vehicle ({known})")


def _manoeuvre_angles_rad(record: StateRecord) -> tuple[float, float]:
    """The zigzag's plane and switching angles from the record's metadata, else the defaults."""
    try:
        return (
            np.radians(float(record.meta.get("delta_deg", DEFAULT_DELTA_DEG))),
            np.radians(float(record.meta.get("theta_deg", DEFAULT_THETA_DEG))),
        )
    except ValueError:
        raise InputError("the record's delta_deg/theta_deg metadata are not numbers") from None


def _sensitivity(
    vehicle: Vehicle, delta_rad: float, theta_rad: float, step: float = 0.10, threshold: float = 0.10
) -> SensitivityResult:
    from ..auv.sensitivity import sensitivity_analysis

    with _progress("sensitivity: re-simulating the zigzag") as update:
        return sensitivity_analysis(
            vehicle, delta_rad, theta_rad, step=step, dominant_threshold=threshold, progress=update
        )


@auv_app.command("simulate")
@handles_errors
def simulate_command(
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            callback=checked(validation.new_file),
            help="Output (a new file): .mcap or .csv, by suffix.",
        ),
    ],
    vehicle_name: str = typer.Option(DEFAULT_VEHICLE, "--vehicle", help="Vehicle in configs/vehicles."),
    manoeuvre: str = typer.Option(
        "zigzag",
        "--manoeuvre",
        help="Manoeuvre: zigzag (stern plane +/-delta, switched when pitch reaches -/+theta).",
    ),
    delta_deg: float = typer.Option(DEFAULT_DELTA_DEG, "--delta", help=DELTA_HELP),
    theta_deg: float = typer.Option(DEFAULT_THETA_DEG, "--theta", help=THETA_HELP),
    switches: int = typer.Option(8, "--switches", help="Plane reversals to record."),
    rate_hz: float = typer.Option(100.0, "--rate-hz", help="Sample rate [Hz]."),
    noise: str = typer.Option("none", "--noise", help="Sensor noise: none, realistic, or a factor of it."),
    seed: int = typer.Option(0, "--seed", help="Noise random seed."),
) -> None:
    """Simulate a diving-plane manoeuvre with the vehicle's standard derivatives and write it."""
    from ..auv.io import write_record
    from ..auv.model import add_noise, simulate_zigzag
    from ..auv.vehicle import load_vehicle

    if manoeuvre != "zigzag":
        raise InputError(f"--manoeuvre {manoeuvre!r} unknown; the only manoeuvre is zigzag")
    if not 1 <= rate_hz <= 1000:
        raise InputError(f"--rate-hz {rate_hz:g} must be between 1 and 1000")
    scale = parse_noise(noise)
    vehicle = load_vehicle(vehicle_name)
    record = simulate_zigzag(
        vehicle, np.radians(delta_deg), np.radians(theta_deg), switches=switches, rate_hz=rate_hz
    )
    record = add_noise(record, scale, seed) if scale > 0 else record
    record.meta.update(
        {
            "noise": "none" if scale == 0 else f"{scale:g} x realistic",
            "seed": str(seed),
            "rate_hz": f"{rate_hz:g}",
        }
    )
    path = write_record(out, record, vehicle)
    typer.echo(
        f"wrote {path}: {vehicle.name} zigzag {delta_deg:g}/{theta_deg:g} deg, "
        f"{record.t.size} samples over {record.t[-1]:.1f} s, {switches} plane reversals, "
        f"noise {record.meta['noise']}"
    )


def _print_identify(report: dict) -> None:
    typer.echo(
        f"{report['vehicle']}: separate identification by {report['method']} "
        f"(weak-form window {report['window_s']:.2f} s); prime-system derivatives"
    )
    typer.echo(
        f"{'derivative':<10} {'standard':>11} {'identified':>11} {'std err':>10} {'rel err':>9} "
        f"{'sensitivity':>11}"
    )
    for row in report["derivatives"]:
        err = f"{100 * row['relative_error']:.2f} %" if row["relative_error"] is not None else "-"
        sens = f"{row['sensitivity_index']:.3f}" if row["sensitivity_index"] is not None else "-"
        mark = " *" if row["dominant"] else ""
        typer.echo(
            f"{row['derivative']:<10} {row['standard']:>11.4g} {row['identified']:>11.4g} "
            f"{row['std_error']:>10.2g} {err:>9} {sens:>11}{mark}"
        )
    for eq, bias in report["bias"].items():
        gamma = report["gamma"][eq]
        gamma_text = f", gamma {gamma:.3g} (on {report['gamma_chosen_on']})" if gamma is not None else ""
        typer.echo(
            f"{eq} equation: bias {bias:.3g} +/- {report['bias_std'][eq]:.2g}, "
            f"R^2 {report['r2_equation'][eq]:.5f}{gamma_text}"
        )
    summary = report.get("sensitivity_vs_error")
    if summary:
        typer.echo(
            "* dominant (sensitivity index >= 0.1). Sensitivity vs identification error: Spearman rho "
            f"{summary['spearman_rho']:.2f} (p {summary['p_value']:.3f}); mean error of the more "
            f"sensitive half {100 * summary['mean_error_top_half']:.2f} %, of the less sensitive half "
            f"{100 * summary['mean_error_bottom_half']:.2f} %"
        )


@auv_app.command("identify")
@handles_errors
def identify_command(
    file: Annotated[Path, typer.Argument(help="A record written by `tankdaq auv simulate` (.mcap or .csv).")],
    vehicle_name: str = typer.Option(None, "--vehicle", help=RECORD_VEHICLE_HELP),
    method: str = typer.Option("lssvm", "--method", help="lssvm (linear kernel, gamma) or ols."),
    window_s: float = typer.Option(None, "--window", help="Weak-form filter width [s] (default: L/U)."),
    holdout: Annotated[
        Path | None,
        typer.Option(
            "--holdout", help="A second manoeuvre on which LS-SVM picks gamma (default: blocked folds)."
        ),
    ] = None,
    with_sensitivity: bool = typer.Option(
        True,
        "--sensitivity/--no-sensitivity",
        help="Rank the derivatives by sensitivity next to their errors.",
    ),
    as_json: JsonOutput = False,
) -> None:
    """Identify the surge, heave and pitch derivatives one equation at a time; compare with the standard."""
    from ..auv.identify import SeparateIdentifier
    from ..auv.io import read_record
    from ..auv.report import identification_report

    _check_method(method)
    if window_s is not None and window_s <= 0:
        raise InputError(f"--window {window_s:g} must be positive (seconds)")
    record = read_record(file)
    vehicle = _vehicle_for(file, record, vehicle_name)
    held_out = read_record(holdout) if holdout is not None else None
    ident = SeparateIdentifier(vehicle, method=method, window_s=window_s).fit(record, held_out)
    sensitivity = _sensitivity(vehicle, *_manoeuvre_angles_rad(record)) if with_sensitivity else None
    gamma_source = f"held-out record {holdout}" if holdout is not None else "5 blocked folds of the record"
    report = identification_report(ident, vehicle, sensitivity, gamma_source)
    if as_json:
        typer.echo(json.dumps(report, indent=1))
    else:
        _print_identify(report)


@auv_app.command("sensitivity")
@handles_errors
def sensitivity_command(
    vehicle_name: str = typer.Option(DEFAULT_VEHICLE, "--vehicle", help="Vehicle in configs/vehicles."),
    delta_deg: float = typer.Option(DEFAULT_DELTA_DEG, "--delta", help=DELTA_HELP),
    theta_deg: float = typer.Option(DEFAULT_THETA_DEG, "--theta", help=THETA_HELP),
    step_percent: float = typer.Option(
        10.0,
        "--step",
        callback=checked(validation.percent, option="--step"),
        help="Perturbation of each derivative [%], between 0 and 100.",
    ),
    threshold: float = typer.Option(0.10, "--threshold", help="Index at which a derivative is dominant."),
    as_json: JsonOutput = False,
) -> None:
    """Rank the derivatives by how much the zigzag changes when each is perturbed."""
    from ..auv.sensitivity import OUTPUTS
    from ..auv.vehicle import load_vehicle

    vehicle = load_vehicle(vehicle_name)
    delta_rad, theta_rad = np.radians(delta_deg), np.radians(theta_deg)
    result = _sensitivity(vehicle, delta_rad, theta_rad, step_percent / 100.0, threshold)
    if as_json:
        typer.echo(json.dumps(result.to_dict(), indent=1))
        return
    base = result.baseline
    typer.echo(
        f"{vehicle.name}: zigzag {delta_deg:g}/{theta_deg:g} deg, each derivative perturbed by "
        f"+/-{step_percent:g} %; S = relative output change per relative derivative change"
    )
    typer.echo(
        f"baseline: overshoot {np.degrees(base['overshoot']):.2f} deg, depth change "
        f"{base['depth_change']:.2f} m, period {base['period']:.1f} s, speed {base['speed']:.3f} m/s"
    )
    typer.echo(f"{'rank':<5}{'derivative':<11}" + "".join(f"{o:>13}" for o in OUTPUTS) + f"{'index':>9}")
    for rank, name in enumerate(result.ranking, start=1):
        cells = "".join(f"{result.sensitivities[name][o]:>13.4f}" for o in OUTPUTS)
        mark = "  dominant" if name in result.dominant else ""
        typer.echo(f"{rank:<5}{name:<11}{cells}{result.index[name]:>9.4f}{mark}")


@auv_app.command("validate")
@handles_errors
def validate_command(
    file: Annotated[Path, typer.Argument(help="Record to identify from (.mcap or .csv).")],
    test: Annotated[Path | None, typer.Option("--test", help="Held-out record (default: FILE).")] = None,
    vehicle_name: str = typer.Option(None, "--vehicle", help=RECORD_VEHICLE_HELP),
    method: str = typer.Option("lssvm", "--method", help="lssvm or ols."),
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            callback=checked(validation.new_file, option="--plot"),
            help="PNG: measured vs re-simulated.",
        ),
    ] = None,
    mode: str = typer.Option(
        None,
        "--mode",
        help="zigzag (re-run the manoeuvre; default for zigzag records) "
        "or replay (driven by the measured plane).",
    ),
    as_json: JsonOutput = False,
) -> None:
    """Re-simulate a manoeuvre with the identified model (all derivatives, dominant ones) and score it."""
    from ..auv.io import read_record
    from ..auv.report import validate_models
    from ..auv.validate import MODES, SCORED_STATES, default_mode

    _check_method(method)
    if plot is not None and plot.suffix.lower() != ".png":
        raise InputError(f"--plot {plot}: the plot is written as PNG; give a file name ending in .png")
    if mode is not None and mode not in MODES:
        raise InputError(f"--mode {mode!r} unknown; use {' or '.join(MODES)}")
    record = read_record(file)
    vehicle = _vehicle_for(file, record, vehicle_name)
    target = read_record(test) if test is not None else record
    mode = mode or default_mode(target)
    sensitivity = _sensitivity(vehicle, *_manoeuvre_angles_rad(record))
    validation = validate_models(record, target, vehicle, sensitivity, method, mode, str(test or file))
    results, failures = validation.results, validation.failures
    if plot is not None:
        from ..viz.auv_view import validation_figure
        from ..viz.plots import save_png

        save_png(validation_figure(target, results), plot, dpi=110)
    report = {
        "train": str(file),
        "test": str(test or file),
        "mode": mode,
        "dominant": validation.dominant,
        "r2": {r.label: r.r2 for r in results},
        "failed": failures,
        "plot": str(plot) if plot else None,
    }
    if as_json:
        typer.echo(json.dumps(report, indent=1))
        return
    how = "the zigzag re-run with each model" if mode == "zigzag" else "driven by its measured stern plane"
    typer.echo(f"identified from {file}, re-simulated {test or file} ({how})")
    typer.echo(f"dominant derivatives: {', '.join(validation.dominant)}")
    typer.echo(f"{'model':<38}" + "".join(f"{'R2 ' + s:>10}" for s in SCORED_STATES))
    for result in results:
        typer.echo(f"{result.label:<38}" + "".join(f"{result.r2[s]:>10.4f}" for s in SCORED_STATES))
    for label, reason in failures.items():
        typer.echo(f"{label:<38} could not be re-simulated: {reason}")
    if plot is not None:
        typer.echo(f"plot: {plot}")
