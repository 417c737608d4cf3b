"""``tankdaq identify``: damping and restoring coefficients from decay recordings or CSV files."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from .. import validation
from ..errors import InputError
from ..records import DecayRun

if TYPE_CHECKING:
    from ..catalogue.hooks import CatalogueWriter
    from ..config import Hull
from .app import (
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
    """The free decays of every input, read through the one way in (``ident.inputs.read_decays``: the
    reader by suffix, CSV releases found), each cut where its free part ends (``ident.free_decay``;
    ``start_s``/``end_s`` override).

    Without ``axis`` a recording's decays are read on the axis its metadata names. What the reading
    decided (a CSV's dialect and units, decays found, parts not used) is said in one line each.
    """
    from ..ident.free_decay import cut_free_decays
    from ..ident.inputs import input_notices, read_decays

    runs = [
        run
        for path in inputs
        for run in read_decays(
            path, axis, time_col, angle_col, rate_col, angle_unit, keep_all, skip_half_cycles, time_unit
        )
    ]
    for line in input_notices(runs):
        say(line)
    return cut_free_decays(runs, start_s, end_s)


def _json_default(value: object) -> object:
    """NaN/inf become null so the output stays valid JSON."""
    return None if isinstance(value, float) and not math.isfinite(value) else str(value)


def _clean(value: object) -> object:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


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
    from ..catalogue.hooks import CatalogueWriter
    from ..catalogue.query import inputs_or_query
    from ..config import full_scale_of, load_hull
    from ..ident.conditions import condition_of, group_conditions, grouping_line
    from ..ident.derived import scale_results
    from ..ident.estimators import make_estimator
    from ..ident.intervals import check_intervals
    from ..ident.online import prepare_identifier
    from ..ident.report import text_report
    from ..physics.models import MODEL_FAMILY, is_auto, resolve_model

    writer = CatalogueWriter.from_option(catalogue, say)  # a --catalogue not understood: one line, now
    inputs = inputs_or_query(inputs, runs_query, catalogue)
    if axis not in (None, "roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
    hull_config = load_hull(hull) if hull else None
    scale = full_scale_of(hull_config, full_scale)
    terms = None if is_auto(model) else resolve_model(model)
    probe = make_estimator(method, terms or MODEL_FAMILY[0])  # an unknown method fails before any reading
    runs = load_runs(
        inputs, axis, time_col, angle_col, rate_col, angle_unit, keep_all, skip_half_cycles, start, end,
        time_unit,
    )  # fmt: skip
    if hull_config is not None:  # the draft must be one the hull has on the decays' axes, before any fit
        for run_axis in sorted({run.axis for run in runs}):
            validation.hull_draft(hull_config, draft, run_axis)
    truncated = {"truncated": bool(cut := warn_truncated(runs)), "truncated_files": cut}
    groups = group_conditions(runs)
    pooled = grouping_line(groups, joint=True) if len(groups) > 1 and (joint or compare) else None
    fits = [runs] if joint or len(groups) == 1 else list(groups.values())
    for condition_runs in fits if not compare else []:  # impossible interval requests fail before any fit
        check_intervals(probe, len(condition_runs), bootstrap, repeats, method)
    build_kernels_shown()
    prepare_identifier(terms or MODEL_FAMILY[-1], say)  # the native kernels: built once, on the first run

    if compare:
        _compare(runs, method, as_json, truncated, pooled)
        return
    if len(fits) > 1:
        say(grouping_line(groups))
    summaries, scaled_lines = [], []
    for condition_runs in fits:
        label = "all conditions (--joint)" if pooled else condition_of(condition_runs[0]).label
        summary = _fit_condition(condition_runs, terms, method, bootstrap, repeats, hull_config, draft, label)
        summary["condition"] = None if pooled else condition_of(condition_runs[0]).as_dict()
        if pooled is not None:
            summary["warnings"].insert(0, pooled)
            summary["conditions"] = pooled
        summaries.append(summary)
        scaled_lines.append(scale_results(summary, hull_config, draft, scale))  # B̂44; the ship's
        if pooled is None:  # a fit of one condition: the rows of its recordings carry it
            _catalogue_fit(writer, "identify", summary, condition_runs)
    writer.close()
    if len(summaries) == 1:
        document: dict[str, object] = {**summaries[0], **truncated}
    else:
        warnings = [f"{g['condition_label']}: {line}" for g in summaries for line in g["warnings"]]
        document = {
            "conditions": grouping_line(groups),
            "groups": summaries,
            "warnings": warnings,
            **truncated,
        }
    if as_json:
        typer.echo(json.dumps(_clean(document), default=_json_default))
        return
    for summary, scaled in zip(summaries, scaled_lines, strict=True):
        if len(summaries) > 1:
            typer.echo(f"== {summary['condition_label']} ==")
        typer.echo("\n".join([text_report(summary), *scaled]))
        if len(summaries) > 1:
            typer.echo("")


def _compare(runs: list[DecayRun], method: str, as_json: bool, truncated: dict, pooled: str | None) -> None:
    """``--compare``: every seed formula and ITTC form fitted to ``runs``, the table printed."""
    from ..ident.comparison import compare_models, compare_text, group_models
    from ..ident.free_decay import cut_lines
    from ..physics.models import COMPARE_MODELS

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
            **truncated,
        }
        typer.echo(json.dumps(_clean(document), default=_json_default))
    else:
        echo_cuts(runs)
        typer.echo(compare_text(rows))


def _fit_condition(
    runs: list[DecayRun],
    terms: tuple[str, ...] | None,
    method: str,
    bootstrap: int,
    repeats: bool,
    hull_config: Hull | None,
    draft: float,
    label: str,
) -> dict:
    """One fit of ``runs`` (the model chosen by data when ``terms`` is None) and its summary."""
    from ..ident.estimators import make_estimator, reports_progress
    from ..ident.intervals import fit_with_intervals
    from ..ident.model_choice import choose_model
    from ..ident.report import summarize

    choice = None
    if terms is None:
        with progress_bar() as progress:
            progress.add_task(f"choosing the model ({label})", total=None)
            particulars = hull_config.particulars(runs[0].axis) if hull_config is not None else None
            choice = choose_model(
                runs, particulars=particulars, hull=getattr(hull_config, "name", "the hull")
            )
        terms = choice.terms
        say(f"{label}: {choice.reason}")
    repeats_of = (lambda: make_estimator(method, terms)) if repeats else None
    with progress_bar() as progress:
        task = progress.add_task(f"fitting {method}", total=1 + bootstrap)
        settings: dict[str, Any] = {}
        if reports_progress(method):  # the seeds' GA/PSO (about 100 s): their generations
            generations = progress.add_task("generations", total=None)
            settings["progress"] = lambda done, of: progress.update(generations, completed=done, total=of)
        estimator = make_estimator(method, terms, **settings)
        estimator, intervals = fit_with_intervals(
            estimator,
            runs,
            bootstrap,
            repeats_of,
            progress=lambda done: progress.update(task, completed=done),
            method=method,
        )
    summary = summarize(estimator, runs, method, hull_config, draft, intervals)
    summary["condition_label"] = label
    given = {"chosen": ",".join(terms), "reason": "given by --model"}
    summary["model_choice"] = choice.as_dict() if choice is not None else given
    return summary


def _catalogue_fit(writer: CatalogueWriter, source: str, summary: dict, runs: list[DecayRun]) -> None:
    """A condition's fit onto its recordings' catalogue rows (identify, diagnose)."""
    from ..catalogue.writing import fit_of_summary, run_paths

    writer.add_fit(run_paths(runs), fit_of_summary(source, summary, runs))
