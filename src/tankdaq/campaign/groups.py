"""A test campaign: many decays grouped by hull, axis, draft and initial angle, one joint fit per group.

This is the seeds' workflow (three drafts x four initial angles per hull, coefficients plotted against
the initial angle, two hulls compared) done with output error and the ITTC quantities people report:
B_eq against amplitude, extinction curves, natural period against draft. Recordings come from tankdaq
MCAP files (their metadata says hull, draft, axis, angle) or CSV files (a JSON sidecar or a file name
``hull_draft_axis_<angle>deg...``, the name tankdaq gives its recordings).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from ..config.hulls import Hull, format_draft, load_hull, parse_draft
from ..config.rules import safe_name
from ..config.validation import refuse_existing
from ..errors import IdentificationError, InputError, RecordingError, TankdaqError
from ..ident.budget import EXPANDED_LABEL, short_lines
from ..ident.budget_fit import group_budgets
from ..ident.derived import amplitude_table, b44_hat_factor, damping_ratio, natural_period
from ..ident.free_decay import cut_free_decays, cut_lines
from ..ident.imo_table import DecayCover, decay_cover, imo_markdown, imo_tables
from ..ident.inputs import read_decays
from ..ident.interval_labels import FIT_STD
from ..ident.model_choice import model_for
from ..ident.output_error import OutputErrorFit
from ..ident.plausibility import check_runs
from ..physics.models import AUTO
from ..records import DecayRun
from ..samples import AXIS_FIELDS
from ..store.export_layout import export_metadata_of
from ..store.inputs import INPUT_FORMATS, input_format, suffixes
from ..store.naming import parse_recording_name
from ..store.safe_write import write_rows, write_text_new
from .executors import executor_map


@dataclass(frozen=True, order=True)
class GroupKey:
    """What a campaign varies: runs with the same key are repeats and are fitted jointly."""

    hull: str
    axis: str
    draft: float  # factor of the design draft
    angle_deg: float  # nominal initial angle

    @property
    def label(self) -> str:
        return f"{self.hull} {self.axis} {format_draft(self.draft)} {self.angle_deg:g} deg"


@dataclass
class GroupResult:
    """One group's joint output-error fit, or why it could not be made."""

    key: GroupKey
    runs: list[DecayRun]
    fit: OutputErrorFit | None = None
    error: str | None = None
    extra: dict[str, float] = field(default_factory=dict)
    hull: Hull | None = None  # the hull file found for key.hull: dimensional results from its GM
    model_reason: str = ""  # which model was fitted and why (``model_choice.model_for``)
    model_by_data: bool = False  # the data chose it (``auto``), not ``--model``

    @cached_property
    def warnings(self) -> list[str]:
        """The fit's implausibilities (``ident.plausibility``), one line each; none without a fit. Found
        once: a result pickled back from a worker brings them along (the catalogue asks again)."""
        if self.fit is None:
            return []
        particulars = self.hull.particulars(self.key.axis) if self.hull is not None else None
        found = check_runs(self.fit.coefficients_, self.runs, self.fit.offsets_, particulars, self.key.hull)
        return [finding.message for finding in found]

    @cached_property
    def budget(self) -> tuple[dict[str, Any], ...]:
        """The uncertainty budgets, Type A from the group's repeats (``budget_fit.group_budgets``); once."""
        return group_budgets(self.fit, self.runs, self.hull, self.key.draft)

    def summary(self) -> dict[str, Any]:
        """One row of the campaign table (angles in deg, coefficients per unit inertia, SI)."""
        row: dict[str, Any] = {
            "hull": self.key.hull,
            "axis": self.key.axis,
            "draft": format_draft(self.key.draft),
            "angle_deg": self.key.angle_deg,
            "runs": len(self.runs),
            "files": " ".join(str(run.meta.get("file", run.name)) for run in self.runs),
            "cuts": " | ".join(cut_lines(self.runs)),
        }
        if self.fit is None:
            return row | {"error": self.error}
        coefficients = self.fit.coefficients_
        row |= {"model": ",".join(self.fit.terms_), "model_reason": self.model_reason}
        for term, value in coefficients.items():
            row[term] = value
            row[f"{term}_std"] = self.fit.std_[term]
        (at_release,) = amplitude_table(coefficients, self.fit.covariance_, [self.key.angle_deg])
        row |= self._dimensional(coefficients, at_release.b_eq)
        return row | {
            "natural_period_s": natural_period(coefficients),
            "damping_ratio": damping_ratio(coefficients),
            "b_eq_per_s": at_release.b_eq,
            "b_eq_std": at_release.b_eq_std,
            "bertin_n_per_deg": at_release.bertin_n_per_deg,
            "r2_angle": self.fit.r2_angle_,
            "seed_objective_rad_s": self.fit.seed_objective_,
            "error": "",
            "warnings": " | ".join(self.warnings),
        }

    def _dimensional(self, coefficients: dict[str, float], b_eq_per_s: float) -> dict[str, Any]:
        """Total inertia and B_eq in N m s/rad from the hull's displacement and GM (empty without a hull)."""
        if self.hull is None:
            return {}
        from ..ident.report import dimensional_summary

        found = dimensional_summary(coefficients, self.hull, self.key.axis, self.key.draft)
        if "total_inertia_kg_m2" not in found:
            return {}
        inertia = found["total_inertia_kg_m2"]
        row = {"gm_m": found["gm_m"], "total_inertia_kg_m2": inertia, "b_eq_n_m_s": b_eq_per_s * inertia}
        hat = self.b44_hat_per_b_eq()
        return row if hat is None else row | {"b44_hat": b_eq_per_s * hat}

    def b44_hat_per_b_eq(self) -> float | None:
        """B̂44 per B_eq/I (I √(B/2g) / (ρ∇B²), I = Δ g GM / c1 at the group's draft): roll groups whose
        hull gives the displacement, GM and beam; None otherwise (and without a fit)."""
        if self.fit is None or self.hull is None or self.key.axis != "roll":
            return None
        from ..ident.report import dimensional_summary

        found = dimensional_summary(self.fit.coefficients_, self.hull, self.key.axis, self.key.draft)
        factor = b44_hat_factor(self.hull, self.key.draft)
        if factor is None or "total_inertia_kg_m2" not in found:
            return None
        return float(found["total_inertia_kg_m2"] * factor)


# Finding and reading recordings
def find_recordings(inputs: Sequence[str | Path], recurse: bool = True) -> list[Path]:
    """The files tankdaq reads decays from (``store.inputs.INPUT_FORMATS``: .mcap, .csv) among ``inputs``
    (folders searched recursively unless ``recurse`` is False: then only the folder's own files), sorted."""
    found: list[Path] = []
    known = suffixes(INPUT_FORMATS)
    for item in map(Path, inputs):
        if item.is_dir():
            files = item.rglob("*") if recurse else item.iterdir()
            # not is_dir(): a dangling link is kept, to be reported as one (a folder named x.csv is not)
            found.extend(p for p in sorted(files) if not p.is_dir() and p.suffix.lower() in INPUT_FORMATS)
        elif item.is_file():
            if item.suffix.lower() not in INPUT_FORMATS:
                raise InputError(f"{item}: not a recording; give {known} files or a folder of them")
            found.append(item)
        else:
            raise InputError(f"{item}: no such file or folder")
    if not found:
        raise InputError(f"no decay files ({known}) in {', '.join(map(str, inputs))}")
    return sorted(set(found))


def csv_labels(path: Path) -> dict[str, Any]:
    """hull, draft, axis, angle_deg of a decay file that is not a recording (CSV, HDF5, MATLAB, Parquet):
    its JSON sidecar, else the metadata ``tankdaq export`` wrote into it, else its file name."""
    sidecar = path.with_suffix(".json")
    exported = export_metadata_of(path) if path.suffix.lower() != ".csv" else None
    if exported is not None and not sidecar.is_file() and {"hull", "axis", "angle_deg"} <= set(exported):
        return _export_labels(path, exported)
    if sidecar.is_file():
        try:
            data = json.loads(sidecar.read_text())
            return {
                "hull": str(data["hull"]),
                "draft": parse_draft(str(data.get("draft", "T"))),
                "axis": str(data["axis"]),
                "angle_deg": float(data["angle_deg"]),
            }
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise InputError(
                f'{sidecar}: needs JSON with hull, axis, angle_deg (and draft, e.g. "1.1T"): {exc}'
            ) from None
    named = parse_recording_name(path.name)
    if named is None:
        raise InputError(
            f"{path}: cannot tell hull, draft, axis and angle; name it like trimaran_0.9T_pitch_8deg.csv "
            f"or put {sidecar.name} beside it with hull, draft, axis, angle_deg"
        )
    return {"hull": named.hull, "draft": named.draft, "axis": named.axis, "angle_deg": named.angle_deg}


def _export_labels(path: Path, meta: dict[str, object]) -> dict[str, Any]:
    """The labels an export's own metadata gives (hull, draft, axis, angle_deg); one line when one is
    not of its kind (an edited file)."""
    try:
        return {
            "hull": str(meta["hull"]),
            "draft": parse_draft(str(meta.get("draft", "T"))),
            "axis": str(meta["axis"]),
            "angle_deg": float(meta["angle_deg"]),  # type: ignore[arg-type]
        }
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"{path}: its export metadata does not give hull, draft, axis and angle_deg as such ({exc}): "
            "fix them, or put a JSON sidecar beside it"
        ) from None


def read_campaign_runs(
    path: Path, start_s: float | None = None, end_s: float | None = None
) -> list[DecayRun]:
    """The free decays of one file, with hull, axis, draft and nominal angle in ``meta``, each cut where
    its free part ends (``free_decay.cut_free_decay``; ``start_s``/``end_s`` override)."""
    return cut_free_decays(_labelled_runs(path), start_s, end_s)


def _labelled_runs(path: Path) -> list[DecayRun]:
    """The decays of a file (``ident.inputs``), labelled from the recording's metadata or, for a file
    that does not say, from its sidecar or name (``csv_labels``); the hull name becomes part of report
    file names, so it must pass ``config.rules.safe_name``."""
    runs = _read_labelled_runs(path)
    for run in runs:
        safe_name(run.meta["hull"], f"{path}: hull")
    return runs


def _read_labelled_runs(path: Path) -> list[DecayRun]:
    if input_format(path).self_labelled:
        runs = read_decays(path)
        for run in runs:
            missing = [k for k in ("hull", "draft") if run.meta.get(k) is None]
            if missing:
                raise InputError(f"{path}: the recording's metadata lacks {', '.join(missing)}")
            nominal = run.meta.get("angle_nominal_deg")
            run.meta["angle_deg"] = (
                _nominal_deg(path, nominal) if nominal is not None else _rounded_first_peak_deg(run)
            )
        return runs
    labels = csv_labels(path)
    if labels["axis"] not in AXIS_FIELDS:
        raise InputError(f"{path}: axis {labels['axis']!r} not understood; use roll or pitch")
    runs = read_decays(path, axis=labels["axis"])
    for run in runs:
        run.meta.update(labels)
    return runs


def _nominal_deg(path: Path, value: object) -> float:
    """A recording's nominal release angle, which names its group: a number above 0 and up to 45 deg
    (one that is not, an edited or damaged file's, would group and report as -6 or nan deg)."""
    try:
        angle = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        angle = math.nan
    if not 0.0 < angle <= 45.0:
        raise InputError(
            f"{path}: its metadata gives the nominal angle {value!r}, not a release angle (above 0 and up to "
            "45 deg): the file was edited or damaged; fix its angle_nominal_deg or leave the file out"
        )
    return angle


def _rounded_first_peak_deg(run: DecayRun) -> float:
    """The initial angle to the nearest degree when the recording does not state a nominal one."""
    return float(round(abs(math.degrees(float(run.angle[0])))))


def run_key(run: DecayRun) -> GroupKey:
    """The group of a labelled run (``read_campaign_runs``)."""
    return GroupKey(
        str(run.meta["hull"]), run.axis, round(float(run.meta["draft"]), 6), float(run.meta["angle_deg"])
    )


def group_runs(runs: Iterable[DecayRun]) -> dict[GroupKey, list[DecayRun]]:
    """Runs by (hull, axis, draft, nominal angle), in sorted key order."""
    groups: dict[GroupKey, list[DecayRun]] = defaultdict(list)
    for run in runs:
        groups[run_key(run)].append(run)
    return dict(sorted(groups.items()))


# Identifying
def find_campaign_hulls(names: Iterable[str], given: Sequence[str] = ()) -> dict[str, Hull]:
    """The hull file of each name: ``given`` (paths or names, e.g. ``campaign --hull``) first, then the
    user folder and the shipped ones; a name with no file is left out (its groups get no dimensional
    results, nothing else changes)."""
    hulls = {hull.name: hull for hull in map(load_hull, given)}
    for name in set(names) - set(hulls):
        try:
            hulls[name] = load_hull(name)
        except InputError:
            continue
    return hulls


def fit_group(key: GroupKey, runs: list[DecayRun], model: str, hull: Hull | None) -> GroupResult:
    """The unit of work of a campaign: one group's runs in, its fit record out (pure, picklable).

    A group that cannot be fitted keeps its reason instead of a fit.
    """
    try:
        choice = model_for(runs, model)  # as ``identify`` chooses for these decays
        fit = OutputErrorFit(choice.terms).fit(runs)
        return GroupResult(
            key, runs, fit=fit, hull=hull, model_reason=choice.reason, model_by_data=choice.by_data
        )
    except IdentificationError as exc:
        return GroupResult(key, runs, error=str(exc), hull=hull)


def identify_groups(
    groups: dict[GroupKey, list[DecayRun]],
    model: str = AUTO,
    progress: Callable[[GroupKey], None] | None = None,
    hulls: dict[str, Hull] | None = None,
    executor: Executor | None = None,
) -> list[GroupResult]:
    """One joint output-error fit per group (``fit_group``), in key order.

    ``progress`` is called after each group, so a long campaign shows where it is. ``hulls`` (by name)
    give the groups' dimensional results (GM, displacement); see ``find_campaign_hulls``. ``executor``
    (see ``campaign_executor``) spreads the groups over cores or machines; the results are the same.
    """
    keys = list(groups)
    found = [(hulls or {}).get(key.hull) for key in keys]
    results = []
    fits = executor_map(executor, fit_group, keys, [groups[k] for k in keys], [model] * len(keys), found)
    for key, result in zip(keys, fits, strict=True):
        results.append(result)
        if progress is not None:
            progress(key)
    return results


@dataclass(frozen=True)
class SkippedFile:
    """A file a campaign could not read, and why (one line: what to do about it)."""

    path: Path
    reason: str

    @property
    def line(self) -> str:
        named = str(self.path) in self.reason
        return f"skipped: {self.reason}" if named else f"skipped: {self.path}: {self.reason}"


@dataclass
class CampaignRead:
    """The free decays of every file read, and the files skipped (the campaign goes on without them)."""

    runs: list[DecayRun]
    skipped: list[SkippedFile]


def read_campaign_file(
    path: Path, start_s: float | None = None, end_s: float | None = None
) -> list[DecayRun] | SkippedFile:
    """``read_campaign_runs``, or why the file cannot be read: one bad file (a recording cut to nothing,
    another tool's MCAP, a CSV with no decay) must not stop a campaign of many (pure, picklable)."""
    if path.is_symlink() and not path.exists():
        return SkippedFile(path, f"{path} is a dangling link (to {path.readlink()}, which does not exist)")
    try:
        return read_campaign_runs(path, start_s, end_s)
    except TankdaqError as exc:
        return SkippedFile(path, str(exc))


def read_campaign(
    paths: Sequence[Path],
    start_s: float | None = None,
    end_s: float | None = None,
    executor: Executor | None = None,
) -> CampaignRead:
    """Every recording's free decays (``read_campaign_file``), in path order, and the files skipped,
    all held here: for a few files (a test, a bench); ``tankdaq.campaign``, which the command and the
    guided session's report call, streams (``campaign.stream``), its parent holding no decay."""
    found = CampaignRead([], [])
    n = len(paths)
    for runs in executor_map(executor, read_campaign_file, paths, [start_s] * n, [end_s] * n):
        if isinstance(runs, SkippedFile):
            found.skipped.append(runs)
        else:
            found.runs.extend(runs)
    return found


# Tables: CSV and Markdown (the figures are drawn by viz.campaign_report)
@dataclass(frozen=True)
class GroupRow:
    """One group's row of the campaign table (``GroupResult.summary``), its fitted terms and warnings:
    what a streamed campaign keeps of a group (``campaign.stream``); the whole ``GroupResult``
    (fit and runs) only when asked for (the report's figures draw them)."""

    key: GroupKey
    row: dict[str, Any]
    terms: tuple[str, ...]  # empty when the group was not fitted
    warnings: tuple[str, ...]
    result: GroupResult | None = None
    cover: DecayCover | None = None  # what the group gives the IMO table (``ident.imo_table``)
    budget: tuple[dict[str, Any], ...] = ()  # ``Budget.as_dict``s, Type A from the repeats

    @classmethod
    def of(cls, result: GroupResult, keep: bool = False) -> GroupRow:
        fit, kept = result.fit, result if keep else None
        terms, cover = (tuple(fit.terms_), decay_cover(result.key, result.runs, fit)) if fit else ((), None)
        return cls(result.key, result.summary(), terms, tuple(result.warnings), kept, cover, result.budget)

    @property
    def error(self) -> str | None:
        """Why the group was not fitted; None when it was."""
        return None if self.terms else str(self.row.get("error"))


def table_rows(results: Sequence[GroupResult | GroupRow]) -> list[GroupRow]:
    """The table's rows of fits or of rows already made."""
    return [r if isinstance(r, GroupRow) else GroupRow.of(r) for r in results]


def write_csv(results: Sequence[GroupResult | GroupRow], path: Path) -> Path:
    """The campaign's table as a new CSV file."""
    return write_rows([r.row for r in table_rows(results)], path)


def markdown_table(results: Sequence[GroupResult | GroupRow]) -> str:
    """The campaign as a Markdown table: coefficients ± (1σ, fit), period, B_eq at the initial angle, R²."""
    rows = table_rows(results)
    terms = list(dict.fromkeys(t for r in rows for t in r.terms))
    hat = any("b44_hat" in r.row for r in rows)  # B̂44 where a hull gives the beam and the inertia
    header = ["hull", "axis", "draft", "angle deg", "runs", *terms, "T0 s", "zeta", "B_eq/I 1/s"]
    header += ["B̂44", "R² angle"] if hat else ["R² angle"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for result in rows:
        row = result.row
        cells = [row["hull"], row["axis"], row["draft"], f"{row['angle_deg']:g}", str(row["runs"])]
        if result.error is not None:
            cells += [f"not fitted: {result.error}"] + [""] * (len(header) - len(cells) - 1)
        else:
            cells += [f"{row[t]:.4g} ± {row[t + '_std']:.2g}" if t in row else "" for t in terms]
            cells += [
                f"{row['natural_period_s']:.4g}",
                f"{row['damping_ratio']:.3g}",
                f"{row['b_eq_per_s']:.4g} ± {row['b_eq_std']:.2g}",
                *([f"{row['b44_hat']:.4g}" if "b44_hat" in row else ""] if hat else []),
                f"{row['r2_angle']:.4f}",
            ]
        lines.append("| " + " | ".join(cells) + " |")
    chosen = [f"- {r.key.label}: {r.row['model_reason']}" for r in rows if r.row.get("model_reason")]
    if chosen:  # which model each group was fitted with, and why (ident.model_choice.model_for)
        lines += ["", "Models (docs/models.md):", "", *chosen]
    lines += ["", f"Every ± is {FIT_STD} (docs/intervals.md)."]
    budget = [line for r in rows for line in short_lines(r.key.label, r.budget)]
    if budget:  # each group's period and B_eq/I with their expanded uncertainty (every source: --json)
        lines += ["", f"Uncertainty (GUM budget; {EXPANDED_LABEL}; every source in --json):", "", *budget]
    implausible = [f"- {r.key.label}: {line}" for r in rows for line in r.warnings]
    if implausible:
        lines += ["", "Warnings (physically implausible fits, docs/models.md):", "", *implausible]
    return "\n".join(lines) + "\n"


#: The report's tables, by name: a ``--report`` folder holding one is refused before the campaign starts.
REPORT_TABLES = ("campaign.csv", "campaign.md")


def write_tables(results: Sequence[GroupResult], folder: Path) -> list[Path]:
    """campaign.csv and campaign.md (where each record was cut, then the table) into ``folder``
    (created), each a new file (``REPORT_TABLES``); the figures are ``viz.campaign_report``'s."""
    csv_path, md = (folder / name for name in REPORT_TABLES)
    refuse_existing([csv_path, md])
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordingError(f"cannot create report folder {folder}: {exc.strerror or exc}") from None
    cuts = "".join(f"- {line}\n" for r in results for line in cut_lines(r.runs))
    rows = table_rows(results)
    write_csv(rows, csv_path)
    write_text_new(
        md,
        "# Decay campaign\n\nWhere each record's free decay was cut, and why:\n\n"
        f"{cuts}\nCoefficients per unit total inertia (SI, rad), {FIT_STD} (docs/intervals.md).\n\n"
        + markdown_table(rows)
        + imo_markdown(imo_tables(r.cover for r in rows if r.cover is not None)),
    )
    return [csv_path, md]
