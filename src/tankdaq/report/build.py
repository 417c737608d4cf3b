"""A report's content from its fits: the conditions, one section per condition (coefficients, B_eq and
Bertin's N, full scale, figures, the condition's warnings beside its numbers), every warning together,
and the provenance last. Nothing is rendered here."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..ident.conditions import UNKNOWN
from ..ident.interval_labels import EXPANDED_U, FIT_95, STANDARD_U
from . import slots
from .content import NOT_KNOWN, Figure, ReportContent, ReportTable, Section
from .tables import coefficients_table, conditions_table, damping_table, decays_table, full_scale_tables

if TYPE_CHECKING:
    from ..api.identification import ConditionFit

TITLE = "Decay test report"


def condition_section(number: int, fit: ConditionFit, extra: Sequence[ReportTable] = ()) -> Section:
    """One condition: its coefficients, its B_eq/N table, its full scale (when asked), then ``extra``
    (an uncertainty budget, the IMO table, the friction-corrected full scale: ``report.slots``), its
    figures, and its warnings as notes beside the numbers."""
    summary = fit.summary
    key = f"c{number}"
    tables = [
        coefficients_table(f"{key}-coefficients", summary),
        damping_table(f"{key}-damping", summary),
        *full_scale_tables(f"{key}-full-scale", summary),
        *extra,
    ]
    chosen = [summary.model_choice.reason] if summary.model_choice else []
    notes = [*(f"warning: {line}" for line in summary.warnings), *chosen]
    return Section(key, fit.label, tables, condition_figures(key, fit), notes)


def budget_tables(key: str, fit: ConditionFit) -> list[ReportTable]:
    """The condition's uncertainty: each reported quantity with u_c and U (k = 2) in one table, then each
    quantity's budget (source, kind, u, sensitivity, contribution, share)."""
    from ..api.identification import budget_table

    budgets = fit.summary.budget or ()
    if not budgets:
        return []
    columns = ["quantity", "value", "unit", STANDARD_U.text, EXPANDED_U.text, "largest source"]
    rows = [
        [b["quantity"], b["value"], b["unit"], b["combined_u"], b["expanded_u"],
         max(b["rows"], key=lambda r: r["share"])["source"] if b["rows"] else NOT_KNOWN]
        for b in budgets
    ]  # fmt: skip
    notes = sorted({note for b in budgets for note in b.get("notes", [])})
    summary = ReportTable(
        f"{key}-uncertainty", "Uncertainty of each reported quantity (ISO GUM)", columns, rows,
        " ".join([f"{STANDARD_U.text}: combined standard uncertainty; {EXPANDED_U.text}: expanded, k = 2.",
                  *notes]),
        {STANDARD_U.text: STANDARD_U, EXPANDED_U.text: EXPANDED_U},
    )  # fmt: skip
    frame = budget_table([(fit.label, budgets)])
    per_quantity = [
        slots.budget_table(
            f"{key}-budget-{b['key']}", b["quantity"],
            frame[frame.quantity == b["quantity"]][["source", "kind", "u", "u_unit", "sensitivity",
                                                    "contribution", "share"]],
        )
        for b in budgets
    ]  # fmt: skip
    return [summary, *per_quantity]


#: The IMO table's columns as the report names them.
IMO_COLUMNS = {
    "amplitude_deg": "φm (deg)", "bertin_n_per_deg": "Bertin N (1/deg)", "bertin_n_std": "N ±",
    "interval": "interval", "reached": "reached", "initial_angles_deg": "from initial angles (deg, measured)",
    "needed_initial_deg": "initial angle needed (deg)",
}  # fmt: skip


@dataclass(frozen=True)
class _ImoCondition:
    """The condition an IMO table is labelled with (``ident.imo_table``'s key)."""

    hull: str
    axis: str
    draft: float
    angle_deg: float


def imo_section(key: str, fit: ConditionFit) -> ReportTable:
    """Bertin's N at 10, 15, 20 and 25 deg from the condition's fit where its decays pass through them,
    and the line on what they do not reach (which initial angles would)."""
    from ..api.campaigns import imo_frame
    from ..config.hulls import parse_draft
    from ..ident.imo_table import decay_cover, imo_table

    condition = fit.summary.condition or {}
    draft = condition.get("draft", UNKNOWN)
    angles = [run["initial_angle_deg"] for run in fit.summary.runs]
    named = _ImoCondition(
        str(condition.get("hull", UNKNOWN)), fit.summary.axis,
        math.nan if draft == UNKNOWN else parse_draft(str(draft)), float(np.mean(np.abs(angles))),
    )  # fmt: skip
    table = imo_table([decay_cover(named, fit.runs, fit.estimator)])
    frame = imo_frame([table]).drop(columns=["hull", "axis", "draft"])
    frame["initial_angles_deg"] = [
        ", ".join(f"{a:.2f}" for a in angles) for angles in frame.initial_angles_deg
    ]
    frame = frame.rename(columns=IMO_COLUMNS)
    return slots.imo_table(key, frame, note=table.missing_line())


def condition_figures(key: str, fit: ConditionFit) -> list[Figure]:
    """B_eq/I and Bertin's N with their 95 % (fit) intervals, then each decay with the model over it."""
    from ..ident.report import covariance_of, predicted_angles
    from ..viz.plots import decay_fit_figure, run_labels
    from ..viz.report_figures import damping_figure, png_bytes

    summary = fit.summary
    amplitudes = [row.amplitude_deg for row in summary.b_eq]
    bertin = [(row.value_per_deg, row.std) for row in summary.bertin_n]
    damping = damping_figure(
        summary.values, covariance_of(fit.estimator), amplitudes, bertin, FIT_95, f"{fit.label}: damping",
    )  # fmt: skip
    figures = [
        Figure(
            f"{key}-damping-figure",
            "B_eq/I and Bertin's N against amplitude",
            png_bytes(damping),
            f"Band and bars: {FIT_95.text}, 1.96 × the standard deviation propagated from the fit's "
            "covariance (delta method).",
            (FIT_95,),
        )
    ]
    predicted = predicted_angles(fit.estimator, fit.runs)
    for number, (run, model, label) in enumerate(
        zip(fit.runs, predicted, run_labels(fit.runs), strict=True), 1
    ):
        figure = decay_fit_figure(run.t - run.t[0], run.angle, model, axis=run.axis, title=label)
        caption = f"{run.name}: measured, the fitted model ({summary.model.name}) and the residual."
        figures.append(Figure(f"{key}-decay-{number}", f"Decay {label}", png_bytes(figure), caption))
    return figures


def report_content(
    fits: Sequence[ConditionFit], warnings: Sequence[str], provenance: Section, made_utc: str
) -> ReportContent:
    """The whole report: conditions and decays, each condition's section, every warning, provenance."""
    summaries = [fit.summary for fit in fits]
    conditions = Section("conditions", "Conditions", [conditions_table(summaries), decays_table(summaries)])
    sections = [
        conditions,
        *(
            condition_section(n, fit, [*budget_tables(f"c{n}", fit), imo_section(f"c{n}-imo", fit)])
            for n, fit in enumerate(fits, 1)
        ),
        provenance,
    ]
    return ReportContent(TITLE, sections, list(warnings), made_utc)
