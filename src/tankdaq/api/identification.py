"""``tankdaq.identify``: the decay equation's coefficients from recordings, CSV files or decays in memory.

This is the one identification pipeline of ``tankdaq identify`` (the command parses its options, calls
``identify`` and prints ``Identification.document``): read through ``ident.inputs`` and cut to the free
decay, grouped by condition (hull, draft, axis) unless ``joint``, the model chosen by the data unless
given, fitted with its intervals, summarised by ``ident.report.summarize`` (plausibility warnings
included), with B̂44 and the full-scale results where a hull allows (``ident.full_scale.scale_results``).
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import validation
from ..errors import InputError
from ..records import DecayRun
from . import arguments
from .progress import Kept, Progress
from .recording import Decay, Recording, columns_given, runs_of, sources_given

if TYPE_CHECKING:
    import pandas as pd

    from ..config.hulls import Hull, WaterSettings
    from ..ident.budget_inputs import DeviceProfile
    from ..ident.intervals import IntervalSummary
    from ..ident.summary import FitSummary
    from ..physics.scaling import FroudeScale
    from ..store.export_layout import ExportOrigin
    from ..viz.plots import Figure

#: What ``identify`` takes: a path, a ``Recording``, a ``Decay`` or a ``DecayRun``, or a list of them.
Source = str | Path | Recording | Decay | DecayRun


@dataclass(frozen=True, eq=False)  # holds DataFrames or fits: compared by identity
class ConditionFit:
    """One fit: the runs of one condition (or of several, ``pooled`` by ``joint``), the fitted estimator,
    its summary (one ``groups`` entry of the JSON) and the lines the text report adds (B̂44, full scale)."""

    label: str
    runs: list[DecayRun]
    estimator: Any
    summary: FitSummary
    scaled_lines: list[str]
    pooled: bool = False


@dataclass(frozen=True)
class FitSettings:
    """How ``identify`` fits each condition (its arguments, checked): one object, not a tuple by position."""

    method: str
    bootstrap: int
    repeats: bool
    hull: Hull | None
    draft: float
    scale: FroudeScale | None
    device: DeviceProfile | None


@dataclass(frozen=True, eq=False)  # holds DataFrames or fits: compared by identity
class Identification:
    """What ``identify`` found. ``document`` is the object ``tankdaq identify --json`` prints (``to_json``
    gives its text); ``fits`` one entry per condition fitted; ``notices`` the lines the reading and the
    model choice had for the user; ``truncated_files`` the recordings that were cut short.

    >>> result = tankdaq.identify("run.mcap")  # doctest: +SKIP
    >>> result.coefficients  # term, value, unit, std, ci95_low, ci95_high  # doctest: +SKIP
    >>> result.warnings  # what physics says is implausible  # doctest: +SKIP
    """

    document: dict[str, Any]
    fits: list[ConditionFit]
    notices: list[str]
    truncated_files: list[str]

    @property
    def warnings(self) -> list[str]:
        """Every plausibility finding and fit warning, as ``--json`` lists them."""
        return list(self.document["warnings"])

    @property
    def coefficients(self) -> pd.DataFrame:
        """One row per term (and condition, when several were fitted apart): the value per unit total
        inertia in SI units and rad, its unit, its standard deviation and 95 % interval."""
        rows = [
            {**self._condition(fit), "term": term, "value": entry.value, "unit": entry.unit, "std": entry.std,
             "ci95_low": entry.ci95[0], "ci95_high": entry.ci95[1]}
            for fit in self.fits
            for term, entry in fit.summary.coefficients.items()
        ]  # fmt: skip
        return self._with_warnings(_table(rows))

    @property
    def derived(self) -> pd.DataFrame:
        """Per tested amplitude: the natural period, B_eq/I, B̂44 (roll, where the hull gives its beam and
        displacement; else NaN) and Bertin's N, with their standard deviations."""
        rows = [
            {**self._condition(fit), "amplitude_deg": b_eq.amplitude_deg,
             "natural_period_s": fit.summary.natural_period_s, "damping_ratio": fit.summary.damping_ratio,
             "b_eq_per_s": b_eq.value_per_s, "b_eq_std_per_s": b_eq.std,
             "b44_hat": math.nan if b_eq.b44_hat is None else b_eq.b44_hat,
             "bertin_n_per_deg": bertin.value_per_deg, "bertin_n_std_per_deg": bertin.std}
            for fit in self.fits
            for b_eq, bertin in zip(fit.summary.b_eq, fit.summary.bertin_n, strict=True)
        ]  # fmt: skip
        return self._with_warnings(_table(rows))

    @property
    def full_scale(self) -> pd.DataFrame:
        """With ``full_scale=True``, per tested amplitude: B_eq/I and B44 (N·m·s/rad) at full scale by
        Froude and friction-corrected, the correction and its share of B44, both Reynolds numbers (roll,
        where the hull gives the particulars; the corrected columns are absent where it does not)."""
        rows = [
            {**self._condition(fit), **row}
            for fit in self.fits
            for row in (fit.summary.full_scale or {}).get("b_eq", [])
        ]
        return self._with_warnings(_table(rows))

    @property
    def budget(self) -> pd.DataFrame:
        """The uncertainty budget (GUM; docs/models.md): one row per quantity and source, with the
        quantity's value, the source's kind (A/B), standard uncertainty u and unit, sensitivity,
        contribution and share, and the quantity's combined u_c (1σ, standard) and expanded U
        (k=2, ≈95 %, expanded)."""
        table = budget_table([(fit.label, fit.summary.budget or ()) for fit in self.fits])
        return self._with_warnings(table if len(self.fits) > 1 else table.drop(columns="condition"))

    def _condition(self, fit: ConditionFit) -> dict[str, str]:
        return {"condition": fit.label} if len(self.fits) > 1 else {}

    def _with_warnings(self, table: pd.DataFrame) -> pd.DataFrame:
        """A table of this fit carries its warnings (``table.attrs["warnings"]``): an implausible result
        is never shown without them."""
        table.attrs["warnings"] = self.warnings
        return table

    def to_json(self) -> str:
        """The text ``tankdaq identify --json`` prints (NaN and infinities as null)."""
        return to_json(self.document)

    def text(self) -> str:
        """The report ``tankdaq identify`` prints."""
        from ..ident.report import text_report

        parts = []
        for fit in self.fits:
            head = [f"== {fit.label} =="] if len(self.fits) > 1 else []
            parts.append("\n".join([*head, text_report(fit.summary), *fit.scaled_lines]))
        return "\n\n".join(parts)

    def plot(self, decay: int = 0, condition: int = 0) -> Figure:
        """The measured decay with the fitted model over it and the residual (angle in deg against the
        time since release): decay number ``decay`` (from 0) of fit ``condition``."""
        from ..ident.report import predicted_angles
        from ..viz.plots import decay_fit_figure

        fit = self.fits[arguments.index(condition, "condition", len(self.fits), "conditions fitted")]
        decay = arguments.index(decay, "decay", len(fit.runs), "decays in this condition")
        run = fit.runs[decay]
        model = predicted_angles(fit.estimator, [run] if len(fit.runs) == 1 else fit.runs)
        found = len(fit.summary.warnings)
        said = f" ({found} warning{'s' if found > 1 else ''}: result.warnings)" if found else ""
        title = f"{run.name}: {fit.summary.model.name}{said}"
        return decay_fit_figure(
            run.t - run.t[0], run.angle, model[0 if len(fit.runs) == 1 else decay], axis=run.axis, title=title
        )

    def _repr_html_(self) -> str:
        heads = "".join(
            f"<p><b>{html.escape(fit.label)}</b>: model {html.escape(fit.summary.model.name)} "
            f"({html.escape(', '.join(fit.summary.model.terms))}), method "
            f"{html.escape(fit.summary.method)}, {len(fit.runs)} run(s), natural period "
            f"{fit.summary.natural_period_s:.4f} s</p>"
            for fit in self.fits
        )
        warnings = "".join(f"<li>warning: {html.escape(line)}</li>" for line in self.warnings)
        return (
            heads
            + (f'<ul style="color:#b00">{warnings}</ul>' if warnings else "")
            + self.coefficients.to_html(index=False)
            + self.derived.to_html(index=False)
        )


#: The columns of a budget's DataFrame (``Identification.budget``, ``Campaign.budget``).
BUDGET_COLUMNS = ["condition", "quantity", "value", "unit", "source", "kind", "u", "u_unit", "sensitivity",
                  "contribution", "share", "combined_u", "expanded_u", "coverage"]  # fmt: skip


def budget_table(conditions: Sequence[tuple[str, Sequence[Mapping[str, Any]]]]) -> pd.DataFrame:
    """Budgets (``Budget.as_dict``) of each condition as one DataFrame, a row per quantity and source."""
    import pandas as pd

    rows = [
        {"condition": label, "quantity": b["quantity"], "value": b["value"], "unit": b["unit"]}
        | {"source": r["source"], "kind": r["kind"], "u": r["u"], "u_unit": r["unit"]}
        | {key: r[key] for key in ("sensitivity", "contribution", "share")}
        | {key: b[key] for key in ("combined_u", "expanded_u", "coverage")}
        for label, found in conditions
        for b in found
        for r in b["rows"]
    ]
    return pd.DataFrame(rows, columns=BUDGET_COLUMNS)


def _table(rows: list[dict[str, Any]]) -> pd.DataFrame:
    import pandas as pd

    return pd.DataFrame(rows)


def to_json(document: dict[str, Any]) -> str:
    """One JSON object as the commands print it: NaN and infinities as null."""
    return json.dumps(_clean(document), default=_json_default)


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


@dataclass(frozen=True)
class Reading:
    """How files are read (``tankdaq identify``'s options; ``device``: of a log of several; ``speed_col``;
    ``sample_rate_hz``: the rate of a text export that does not say it, ``--rate``) and where each free decay
    is cut (``start_s``/``end_s`` from the release; None: to the end found)."""

    axis: str | None = None
    time_col: str = "time_s"
    angle_col: str = "angle_deg"
    rate_col: str | None = "rate_deg_s"
    angle_unit: str | None = None
    time_unit: str | None = None
    keep_all: bool = False
    skip_half_cycles: int = 0
    start_s: float | None = None
    end_s: float | None = None
    sample_rate_hz: float | None = None
    device: str | None = None
    speed_col: str | None = None

    def __post_init__(self) -> None:
        columns = columns_given(
            self.axis, self.time_col, self.angle_col, self.rate_col, self.angle_unit, self.time_unit
        )
        start_s = arguments.optional_number(self.start_s, "start_s", 0.0, unit="seconds from the release")
        end_s = arguments.optional_number(self.end_s, "end_s", 0.0, unit="seconds from the release")
        if start_s is not None and end_s is not None and end_s <= start_s:
            raise InputError(f"end_s: give a time after start_s ({start_s:g} s), not {end_s:g} s")
        checked = (
            *columns, arguments.flag(self.keep_all, "keep_all"),
            arguments.whole(self.skip_half_cycles, "skip_half_cycles", 0, 1000), start_s, end_s,
            arguments.optional_number(self.sample_rate_hz, "sample_rate_hz", 0.1, 100_000, "Hz"),
            *[arguments.optional_text(getattr(self, n), n, "text or None") for n in ("device", "speed_col")],
        )  # fmt: skip
        for field_name, value in zip(self.__dataclass_fields__, checked, strict=True):
            object.__setattr__(self, field_name, value)  # normalised: a numpy float is a float


def load_runs(sources: Source | Sequence[Source], reading: Reading, progress: Progress) -> list[DecayRun]:
    """The free decays of every source: files read through the one way in (``ident.inputs.read_decays``:
    the reader by suffix, a CSV's releases found), decays in memory as they are; each cut where its free
    part ends (``ident.free_decay``). What the reading decided is said in one line each."""
    from ..ident.free_decay import cut_free_decays
    from ..ident.inputs import input_notices, read_decays
    from ..ident.repeats import repeat_line, repeated_decays

    items = [sources] if isinstance(sources, str | Path | Recording | Decay | DecayRun) else list(sources)
    if not items:
        raise InputError("no decays given: give a recording, a CSV file or decays read with tankdaq.read")
    r = reading
    runs: list[DecayRun] = []
    wanted = drop_read_twice([Path(str(item)) for item in items if isinstance(item, str | Path)], progress)
    for item in items:
        if isinstance(item, str | Path):
            if Path(str(item)) not in wanted:
                continue  # a copy or an export of another file, or a file given a second time
            wanted.remove(Path(str(item)))
        given = runs_of(item)
        runs += given if given is not None else read_decays(
            Path(str(item)), r.axis, r.time_col, r.angle_col, r.rate_col, r.angle_unit, r.keep_all,
            r.skip_half_cycles, r.time_unit, r.sample_rate_hz, device=r.device, speed_col=r.speed_col,
        )  # fmt: skip
    if not runs:  # a recording read with no release in it
        raise InputError("no decay to fit: the recordings given hold no release (tankdaq.read says so)")
    for line in input_notices(runs):
        progress.line(line)
    runs = cut_free_decays(runs, r.start_s, r.end_s)
    repeats = repeated_decays(runs)
    for repeat, first in repeats.items():
        progress.line(f"not used: {repeat_line(runs, repeat, first)}")
    return [run for i, run in enumerate(runs) if i not in repeats]


def drop_read_twice(
    paths: list[Path],
    progress: Progress,
    digests: Mapping[Path, str] | None = None,
    origins: Mapping[Path, ExportOrigin | None] | None = None,
) -> list[Path]:
    """``paths`` without the files whose decays another of them holds (``store.inputs.read_twice``: a
    copy, an export of a recording given too, two exports of one recording), each left out said in one
    line; ``digests``, ``origins``: ``read_twice``'s."""
    from ..store.inputs import read_twice

    once: dict[Path, Path] = {}  # resolved -> as given: a file given twice is read once
    for path in paths:
        if path.resolve() in once:
            progress.line(f"not read again: {path} is given twice")
        else:
            once[path.resolve()] = path
    unique = list(once.values())
    twice = read_twice(unique, digests, origins)
    for path, why in twice.items():
        progress.line(f"not read: {path} {why} (the same decays, which would count twice)")
    return [path for path in unique if path not in twice]


def truncations(runs: Sequence[DecayRun]) -> dict[str, str]:
    """The recordings cut short among the decays read: file -> the line that says what to do."""
    return {str(run.meta["file"]): run.meta["truncation"] for run in runs if run.meta.get("truncation")}


def identify(
    sources: Source | Sequence[Source],
    model: str = "auto",
    *,
    method: str = "oe",
    joint: bool = False,
    hull: str | Path | None = None,
    draft: float | str = 1.0,
    full_scale: bool = False,
    water_temperature_c: float | None = None,
    sea_temperature_c: float | None = None,
    bootstrap: int = 0,
    repeats: bool = False,
    reading: Reading = Reading(),
    progress: Progress | None = None,
    device: DeviceProfile | None = None,
) -> Identification:
    """Identify the decay equation's coefficients from free decays; ``tankdaq identify`` is this call.

    ``model``: ``"auto"`` (the data choose from a small family, held-out), terms (``"b1,b2,c1,c3"``) or an
    alias (docs/models.md); ``method``: ``oe`` (output error), ``ee``, ``ga``, ``pso``; decays of different
    conditions are fitted apart unless ``joint``. ``hull`` (a name or a .toml) and ``draft`` (``1.0`` or
    ``"1.1T"``) give dimensional results and B̂44; ``full_scale`` adds the ship's by Froude and, for roll,
    friction-corrected (ITTC 7.5-02-07-04.5; the tank's and the sea's ``water_temperature_c`` and
    ``sea_temperature_c`` in degC, else the hull's keys, else 15 degC; docs/ikeda.md). Intervals
    from the fit, a moving-block ``bootstrap`` or the spread of ``repeats``; each quantity's uncertainty
    budget (``Identification.budget``) with ``device``'s figures (default: the MTi-G's). Bad input raises
    ``tankdaq.errors.InputError`` with one line that says what to do.

    >>> result = tankdaq.identify("run.mcap", model="b1,b2,c1,c3", hull="swath")  # doctest: +SKIP
    >>> result.coefficients.set_index("term")["value"]  # doctest: +SKIP
    >>> result.derived[["amplitude_deg", "b_eq_per_s", "b44_hat"]]  # doctest: +SKIP
    """
    from ..config.hulls import full_scale_of, load_hull
    from ..ident.budget_inputs import DeviceProfile as Profile
    from ..ident.conditions import condition_of, group_conditions, grouping_line
    from ..ident.estimators import make_estimator
    from ..ident.full_scale import friction_for, scale_results
    from ..ident.intervals import check_intervals
    from ..live.preparation import prepare_identifier
    from ..physics.models import MODEL_FAMILY, is_auto, resolve_model

    sources = sources_given(sources)
    model = arguments.model(model)
    method = arguments.text(method, "method", "an estimator's name: oe, ee, ga or pso")
    joint, repeats = arguments.flag(joint, "joint"), arguments.flag(repeats, "repeats")
    full_scale = arguments.flag(full_scale, "full_scale")
    water = water_settings(water_temperature_c, sea_temperature_c)
    hull = arguments.optional_path(hull, "hull", "a hull's name, a .toml path, or None")
    reading = arguments.optional_instance(reading, "reading", Reading, "a Reading or None") or Reading()
    device = arguments.optional_instance(device, "device", Profile, "an ident.budget_inputs.DeviceProfile")
    kept = Kept(arguments.progress(progress))
    draft = validation.draft_factor(arguments.draft(draft))
    bootstrap = arguments.whole(bootstrap, "bootstrap", 0, validation.MAX_BOOTSTRAP_REPLICAS)
    hull_config = load_hull(str(hull)) if hull else None
    scale = full_scale_of(hull_config, full_scale)
    terms = None if is_auto(model) else resolve_model(model)
    probe = make_estimator(method, terms or MODEL_FAMILY[0])  # an unknown method fails before any reading
    runs = load_runs(sources, reading, kept)
    if hull_config is not None:  # the draft must be one the hull has on the decays' axes, before any fit
        for run_axis in sorted({run.axis for run in runs}):
            validation.hull_draft(hull_config, draft, run_axis)
    cut = truncations(runs)
    for line in cut.values():
        kept.line(line)
    groups = group_conditions(runs)
    pooled = grouping_line(groups, joint=True) if len(groups) > 1 and joint else None
    parts = [runs] if joint or len(groups) == 1 else list(groups.values())
    for condition_runs in parts:  # impossible interval requests fail before any fit
        check_intervals(probe, len(condition_runs), bootstrap, repeats, method)
    frictions = [friction_for(hull_config, draft, scale, runs_of, water) for runs_of in parts]  # before fits
    prepare_identifier(terms or MODEL_FAMILY[-1], kept.line)  # native kernels: built on the first run
    if len(parts) > 1:
        kept.line(grouping_line(groups))
    fits = []
    for condition_runs, friction in zip(parts, frictions, strict=True):
        label = "all conditions (--joint)" if pooled else condition_of(condition_runs[0]).label
        settings = FitSettings(method, bootstrap, repeats, hull_config, draft, scale, device)
        estimator, fitted = _fit_condition(condition_runs, model, settings, label, kept)
        condition = None if pooled else condition_of(condition_runs[0]).as_dict()
        warnings = (*([pooled] if pooled else []), *fitted.warnings)
        fitted = replace(fitted, condition=condition, conditions=pooled, warnings=warnings)
        summary, lines = scale_results(fitted, scale, friction)  # the ship's (B̂44 is summarize's)
        fits.append(ConditionFit(label, condition_runs, estimator, summary, lines, pooled is not None))
    return Identification(_document(fits, grouping_line(groups), list(cut)), fits, kept.lines, list(cut))


def water_settings(water_temperature_c: object, sea_temperature_c: object) -> WaterSettings:
    """The water temperatures of ``full_scale``'s friction correction, checked by name (degC)."""
    from ..config.hulls import WaterSettings

    return WaterSettings(
        arguments.optional_number(water_temperature_c, "water_temperature_c", 0.0, 40.0, unit="degC"),
        arguments.optional_number(sea_temperature_c, "sea_temperature_c", 0.0, 40.0, unit="degC"),
    )


def _document(fits: list[ConditionFit], conditions: str, cut: list[str]) -> dict[str, Any]:
    """``tankdaq identify --json``: the one fit's summary, or each condition's under ``groups``."""
    truncated = {"truncated": bool(cut), "truncated_files": cut}
    if len(fits) == 1:
        return {**fits[0].summary.to_dict(), **truncated}
    warnings = [f"{fit.label}: {line}" for fit in fits for line in fit.summary.warnings]
    return {
        "conditions": conditions,
        "groups": [fit.summary.to_dict() for fit in fits],
        "warnings": warnings,
        **truncated,
    }


def _fit_condition(
    runs: list[DecayRun], model: str, settings: FitSettings, label: str, progress: Progress
) -> tuple[Any, FitSummary]:
    """One fit of ``runs`` with the model ``ident.model_choice.model_for`` gives, and its summary."""
    from ..ident.budget_fit import fit_budgets, hull_figures
    from ..ident.estimators import make_estimator, reports_progress
    from ..ident.intervals import fit_with_intervals
    from ..ident.model_choice import model_for
    from ..ident.report import summarize

    method, bootstrap, repeats = settings.method, settings.bootstrap, settings.repeats
    with progress.task(f"choosing the model ({label})"):
        choice = model_for(runs, model)
    progress.line(f"{label}: {choice.reason}")
    terms = choice.terms
    repeats_of = (lambda: make_estimator(method, terms)) if repeats else None
    watched = reports_progress(method)  # the seeds' GA/PSO (about 100 s) report their generations
    with (
        progress.task(f"fitting {method}", 1 + bootstrap) as advance,
        progress.task("generations") if watched else nullcontext() as generations,
    ):
        estimator = make_estimator(method, terms, **({"progress": generations} if watched else {}))
        estimator, intervals = fit_with_intervals(
            estimator, runs, bootstrap, repeats_of, progress=advance, method=method
        )
    summary = summarize(estimator, runs, method, settings.hull, settings.draft, intervals)
    per_decay = None if intervals is None or intervals.counted != "runs" else repeat_rows(intervals)
    scale = None if settings.scale is None else settings.scale.scale
    figures = hull_figures(settings.hull, runs[0].axis, settings.draft, scale)
    tested = [row.amplitude_deg for row in summary.b_eq]
    budgets = fit_budgets(estimator, runs, tested, figures, settings.device, per_decay)
    return estimator, replace(
        summary, condition_label=label, model_choice=choice, budget=tuple(b.as_dict() for b in budgets)
    )


def repeat_rows(intervals: IntervalSummary) -> list[dict[str, float]]:
    """Each repeat's coefficients from a ``--repeats`` interval (its samples are the runs' own fits)."""
    return [dict(zip(intervals.std, row, strict=True)) for row in intervals.samples.tolist()]
