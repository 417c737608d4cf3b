"""A fit's numbers as report tables: conditions and decays, coefficients with their intervals, B_eq/I
with B̂44 and Bertin's N per amplitude, and the full-scale results (``identify``'s summary, each number
as it is there; the intervals labelled by coverage and kind)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ..ident.full_scale import damping_name
from ..ident.interval_labels import FIT_95, FIT_STD
from ..ident.summary import FitSummary
from .content import ReportTable

#: The fit's own intervals: the coefficient's standard deviation and its 95 % interval.
SIGMA_COLUMN = FIT_STD.text
LOW_COLUMN, HIGH_COLUMN = f"{FIT_95.said} low", f"{FIT_95.said} high"


def conditions_table(summaries: Sequence[FitSummary]) -> ReportTable:
    """One row per condition fitted: what was tested and how it was fitted."""
    rows = []
    for s in summaries:
        condition = s.condition or {}
        angles = ", ".join(f"{run['initial_angle_deg']:.2f}" for run in s.runs)
        rows.append([
            s.condition_label, condition.get("hull"), condition.get("draft"), s.axis, len(s.runs),
            angles, s.model.name, s.method, s.intervals, s.r2_angle, s.natural_period_s, s.damping_ratio,
        ])  # fmt: skip
    columns = [
        "condition", "hull", "draft", "axis", "decays", "initial angles measured (deg)", "model",
        "method", "covariance", "R² angle", "natural period (s)", "damping ratio",
    ]  # fmt: skip
    caption = "Each condition (hull, draft, axis) fitted apart; initial angles as measured at the release."
    return ReportTable("conditions", "Conditions", columns, rows, caption)


def decays_table(summaries: Sequence[FitSummary]) -> ReportTable:
    """One row per decay: its file, measured initial angle, samples kept and the fit's R² on it."""
    rows = [
        [s.condition_label, run["name"], run["file"], run["initial_angle_deg"], run["offset_deg"],
         run["samples"], run["r2_angle"], (run.get("cut") or {}).get("line")]
        for s in summaries
        for run in s.runs
    ]  # fmt: skip
    columns = [
        "condition",
        "decay",
        "file",
        "initial angle (deg)",
        "offset (deg)",
        "samples",
        "R² angle",
        "free decay",
    ]
    return ReportTable("decays", "Decays", columns, rows, "Every decay fitted, as read and cut.")


def coefficients_table(key: str, summary: FitSummary) -> ReportTable:
    """The coefficients per unit total inertia (SI, rad) with the fit's 1σ and 95 % interval."""
    rows = [[term, c.value, c.unit, c.std, c.ci95[0], c.ci95[1]] for term, c in summary.coefficients.items()]
    intervals = {SIGMA_COLUMN: FIT_STD, LOW_COLUMN: FIT_95, HIGH_COLUMN: FIT_95}
    caption = (
        f"Model {summary.model.name} ({summary.method}); per unit total inertia, angles in rad. "
        f"{FIT_STD.text}: the fit's standard deviation ({summary.intervals} covariance); "
        f"{FIT_95.text}: its 95 % interval."
    )
    columns = ["term", "value", "unit", SIGMA_COLUMN, LOW_COLUMN, HIGH_COLUMN]
    return ReportTable(key, "Coefficients", columns, rows, caption, intervals)


def damping_table(key: str, summary: FitSummary) -> ReportTable:
    """B_eq/I (with B̂44 where the hull allows) and Bertin's N at the amplitudes the decays cover."""
    hat = any(row.b44_hat is not None for row in summary.b_eq)
    columns = ["amplitude (deg)", "B_eq/I (1/s)", f"B_eq/I {FIT_STD.text}"]
    columns += ["B̂44"] if hat else []
    columns += ["Bertin N (1/deg)", f"Bertin N {FIT_STD.text}"]
    rows = []
    for b, n in zip(summary.b_eq, summary.bertin_n, strict=True):
        row: list[float | None] = [b.amplitude_deg, b.value_per_s, b.std]
        row += [b.b44_hat] if hat else []
        rows.append([*row, n.value_per_deg, n.std])
    intervals = {f"B_eq/I {FIT_STD.text}": FIT_STD, f"Bertin N {FIT_STD.text}": FIT_STD}
    caption = (
        "Equivalent linear damping B_eq/I and Bertin's N (MSC.1/Circ.1200) at amplitudes the decays "
        f"cover; {FIT_STD.text}: propagated from the fit's covariance (delta method)."
        + (" B̂44 = B44 √(B/2g) / (ρ∇B²), non-dimensional." if hat else "")
    )
    return ReportTable(key, "B_eq and Bertin's N", columns, rows, caption, intervals)


def full_scale_tables(key: str, summary: FitSummary) -> list[ReportTable]:
    """The ship's period and coefficients, and B_eq per amplitude, by Froude (``--full-scale``); none
    when not asked."""
    ship = summary.full_scale
    if ship is None:
        return []
    scale = f"1:{ship['scale_factor']:g}"
    coefficients = [
        ["natural period", summary.natural_period_s, ship["natural_period_s"], "s"],
        *[
            [term, summary.coefficients[term].value, value, summary.coefficients[term].unit]
            for term, value in ship["coefficients"].items()
        ],
    ]
    name = damping_name(ship["axis"])
    dimensional = any("b_eq_n_m_s" in row for row in ship["b_eq"])
    columns = ["amplitude (deg)", "B_eq/I ship (1/s)"] + ([f"{name} ship (N·m·s/rad)"] if dimensional else [])
    rows = [
        [row["amplitude_deg"], row["value_per_s"], *([row.get("b_eq_n_m_s")] if dimensional else [])]
        for row in ship["b_eq"]
    ]
    return [
        ReportTable(f"{key}-coefficients", f"Full scale ({scale}): period and coefficients",
              ["quantity", "model", "ship", "unit"], coefficients, ship["note"]),
        ReportTable(f"{key}-damping", f"Full scale ({scale}): damping", columns, rows, ship["note"]),
        *friction_tables(f"{key}-friction", ship),
    ]  # fmt: skip


def friction_tables(key: str, ship: Mapping[str, Any]) -> list[ReportTable]:
    """Froude's B44 beside the friction-corrected one per amplitude, with both Reynolds numbers and the
    assumptions in the caption; where the hull cannot give the correction, the line that says why."""
    if "friction_missing" in ship:
        return [ReportTable(key, "Full scale, friction corrected", ["why not"], [[ship["friction_missing"]]])]
    friction = ship.get("friction")
    if friction is None:
        return []
    name = damping_name(ship["axis"])
    columns = [
        "amplitude (deg)", f"{name} Froude (N·m·s/rad)", f"{name} corrected (N·m·s/rad)",
        "correction (N·m·s/rad)", "share of Froude B44", "Re model", "Re ship",
    ]  # fmt: skip
    rows = [
        [r["amplitude_deg"], r["b_eq_n_m_s"], r["b44_corrected_n_m_s"], r["friction_correction_n_m_s"],
         r["friction_share"], r["reynolds_model"], r["reynolds_ship"]]
        for r in ship["b_eq"]
    ]  # fmt: skip
    caption = (
        "Froude scaling beside the extrapolation corrected for skin friction at the model's and the "
        f"ship's Reynolds numbers: {friction['method']}. Model: {friction['model_water']}; ship: "
        f"{friction['ship_water']}; speed {friction['model_speed_m_s']:g} m/s at model scale "
        f"({friction['speed_from']})."
    )
    return [ReportTable(key, "Full scale, friction corrected", columns, rows, caption)]
