"""Results at full scale (``--full-scale``): Froude scaling and the friction-corrected extrapolation
(ITTC 7.5-02-07-04.5, ``physics.friction_scaling``) side by side, for ``identify`` and ``campaign``.

``full_scale_b44`` is the one way a fit's B44 reaches full scale both ways (the uncertainty budget calls
it too); ``scale_results`` gives an identify summary its ship's part, ``campaign_full_scale`` gives the
campaign's lines. Where the hull lacks a particular the correction needs, one line names the key and the
Froude column is still shown.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from ..config.hulls import WaterSettings, friction_scaling
from ..physics.friction_scaling import FrictionScaling, FullScaleB44, assumption_lines
from ..physics.scaling import FRICTION_NOTE, FroudeScale
from ..records import DecayRun
from .derived import b44_hat_factor, b_eq, equivalent_frequency
from .summary import FitSummary

#: Why a pitch result has no friction correction.
ROLL_ONLY = "no friction correction for pitch: Kato's friction component is a roll damping (Froude only)"
#: Why a result without the inertia has none.
NO_INERTIA = (
    "no friction correction: B44 in N·m·s/rad needs the hull's displacement_kg and gm_m (Froude only)"
)


def damping_name(axis: str) -> str:
    """What people call the dimensional damping of an axis: B44 (roll), B55 (pitch)."""
    return "B44" if axis == "roll" else "B55"


def full_scale_b44(
    coefficients: Mapping[str, float],
    amplitude_rad: float,
    total_inertia_kg_m2: float,
    scaling: FrictionScaling,
) -> FullScaleB44:
    """B44 at full scale at amplitude φa (rad), by Froude and friction-corrected, from the model's decay
    coefficients per unit inertia and its total inertia (kg m²): B_eq/I (``derived.b_eq``) times I at the
    equivalent frequency ω_E(φa), handed to ``FrictionScaling.at``."""
    omega = equivalent_frequency(coefficients, amplitude_rad)
    return scaling.at(b_eq(coefficients, amplitude_rad) * total_inertia_kg_m2, omega, amplitude_rad)


def runs_speed(runs: Sequence[DecayRun]) -> float | None:
    """The carriage speed the recordings say (m/s), when they all say one; else None (the hull's)."""
    speeds = {float(run.meta["speed_m_s"]) for run in runs if run.meta.get("speed_m_s") is not None}
    return speeds.pop() if len(speeds) == 1 and all("speed_m_s" in run.meta for run in runs) else None


def friction_for(
    hull: Any, draft: float, scale: FroudeScale | None, runs: Sequence[DecayRun], water: WaterSettings
) -> FrictionScaling | str | None:
    """The correction for a condition (None without ``--full-scale``), or the line that says why not."""
    if scale is None or hull is None:
        return None
    return friction_scaling(hull, draft, scale, runs_speed(runs), water)


def scale_results(
    summary: FitSummary, scale: FroudeScale | None, friction: FrictionScaling | str | None = None
) -> tuple[FitSummary, list[str]]:
    """With ``scale``, the identify summary with its full-scale results (``summarize`` has put B̂44
    beside B_eq/I already): Froude's and, for roll with the hull's inertia and particulars, the
    friction-corrected B44 per amplitude; and the lines the text report prints for them."""
    if scale is None:
        return summary, []
    inertia = summary.total_inertia_kg_m2
    coefficients = summary.values
    ship: dict[str, Any] = {
        "scale_factor": scale.scale,
        "axis": summary.axis,
        "natural_period_s": scale.time_s(summary.natural_period_s),
        "coefficients": scale.coefficients(coefficients),
        "b_eq": [
            {"amplitude_deg": r.amplitude_deg, "value_per_s": r.value_per_s / math.sqrt(scale.scale)}
            for r in summary.b_eq
        ],
        "note": FRICTION_NOTE,
    }
    if inertia is not None:
        for row, model in zip(ship["b_eq"], summary.b_eq, strict=True):
            row["b_eq_n_m_s"] = scale.damping_n_m_s(model.value_per_s * inertia)
    why = ROLL_ONLY if summary.axis != "roll" else NO_INERTIA if inertia is None else friction
    if isinstance(why, str):
        ship["friction_missing"] = why
    elif isinstance(friction, FrictionScaling) and inertia is not None:
        ship["friction"] = friction.assumptions()
        ship_inertia = scale.inertia_kg_m2(inertia)
        for row in ship["b_eq"]:
            found = full_scale_b44(coefficients, math.radians(row["amplitude_deg"]), inertia, friction)
            row |= corrected_columns(found, ship_inertia)
    return replace(summary, full_scale=ship), full_scale_lines(ship)


def corrected_columns(found: FullScaleB44, ship_inertia_kg_m2: float) -> dict[str, float]:
    """The friction-corrected values of one amplitude, as ``full_scale.b_eq[]`` holds them."""
    return {
        "value_per_s_corrected": found.corrected_n_m_s / ship_inertia_kg_m2,
        "b44_corrected_n_m_s": found.corrected_n_m_s,
        "friction_correction_n_m_s": found.correction_n_m_s,
        "friction_share": found.share,
        "b_f_model_n_m_s": found.friction_model_n_m_s,
        "b_f_model_froude_n_m_s": found.friction_model_froude_n_m_s,
        "b_f_ship_n_m_s": found.friction_ship_n_m_s,
        "reynolds_model": found.reynolds_model,
        "reynolds_ship": found.reynolds_ship,
    }


def full_scale_lines(ship: dict[str, Any]) -> list[str]:
    """The text of a ``full_scale`` part: period, coefficients, then per amplitude B_eq/I and B_eq (B44 for
    roll, B55 for pitch) by Froude and, where made, friction-corrected, with the correction in N·m·s/rad
    and as a share of B44 and both Reynolds numbers; the assumptions; the note."""
    name = damping_name(ship["axis"])
    coefficients = "  ".join(f"{k}={v:.5g}" for k, v in ship["coefficients"].items())
    lines = [
        f"  full scale (1:{ship['scale_factor']:g}): natural period {ship['natural_period_s']:.4g} s",
        f"  {coefficients} (Froude)",
    ]
    if "friction" in ship:
        lines.append(
            f"  {'amplitude':>10}{'B_eq/I 1/s':>12}{f'{name} Froude':>13}{f'{name} corrected':>15}"
            f"{'correction':>12}{'share':>8}{'Re model':>10}{'Re ship':>10}   (N·m·s/rad)"
        )
        for row in ship["b_eq"]:
            lines.append(
                f"  {row['amplitude_deg']:>6.2f} deg{row['value_per_s']:>12.5g}{row['b_eq_n_m_s']:>13.4g}"
                f"{row['b44_corrected_n_m_s']:>15.4g}{row['friction_correction_n_m_s']:>12.4g}"
                f"{row['friction_share']:>8.1%}{row['reynolds_model']:>10.3g}{row['reynolds_ship']:>10.3g}"
            )
        lines += assumption_lines(ship["friction"])
    else:
        for row in ship["b_eq"]:
            b44 = f", {name} {row['b_eq_n_m_s']:.4g} N·m·s/rad" if "b_eq_n_m_s" in row else ""
            lines.append(f"  {row['amplitude_deg']:>8.2f} deg  B_eq/I {row['value_per_s']:.5g} 1/s{b44}")
        if "friction_missing" in ship:
            lines.append(f"  {ship['friction_missing']}")
    return [*lines, f"  note: {FRICTION_NOTE}"]


def campaign_full_scale(results: Sequence[Any], water: WaterSettings | None = None) -> list[str]:
    """``campaign --full-scale``: each fitted group's period, B_eq/I and B44 at full scale (its hull's
    scale factor) by Froude and friction-corrected (roll, where its hull gives the particulars: else a
    line naming the key), B̂44 where the hull gives beam and displacement; the assumptions once per hull."""
    water = water or WaterSettings()
    lines = [f"full scale: {FRICTION_NOTE}"]
    assumed: dict[str, list[str]] = {}
    for result in results:
        if result.fit is None:
            continue
        scale = result.hull.main_particulars.values.get("scale_factor") if result.hull is not None else None
        if scale is None:
            lines.append(
                f"{result.key.label}: no full scale (its hull gives no scale_factor in [particulars])"
            )
            continue
        text, assumptions = _campaign_line(result, FroudeScale(scale), water)
        lines.append(text)
        if assumptions is not None:
            assumed.setdefault(result.key.hull, assumptions)
    for hull, assumptions in assumed.items():
        lines += [f"{hull}:", *assumptions]
    return lines


def _campaign_line(result: Any, froude: FroudeScale, water: WaterSettings) -> tuple[str, list[str] | None]:
    """One group's full-scale line, and its assumption lines when the friction correction was made."""
    row = result.summary()
    axis = result.key.axis
    period = froude.time_s(row["natural_period_s"])
    text = (
        f"{result.key.label}: 1:{froude.scale:g}, natural period {period:.4g} s, "
        f"B_eq/I {row['b_eq_per_s'] / math.sqrt(froude.scale):.4g} 1/s"
    )
    if "b_eq_n_m_s" not in row:
        return text, None
    text += f", {damping_name(axis)} {froude.damping_n_m_s(row['b_eq_n_m_s']):.4g} N·m·s/rad (Froude)"
    factor = b44_hat_factor(result.hull, result.key.draft)
    if factor is not None and axis == "roll":
        text += f", B̂44 {row['b_eq_n_m_s'] * factor:.4g}"
    friction = ROLL_ONLY if axis != "roll" else friction_for(
        result.hull, result.key.draft, froude, result.runs, water
    )  # fmt: skip
    if not isinstance(friction, FrictionScaling):
        return f"{text}; {friction}", None
    found = full_scale_b44(
        result.fit.coefficients_, math.radians(result.key.angle_deg), row["total_inertia_kg_m2"], friction
    )
    text += (
        f"; friction-corrected {found.corrected_n_m_s:.4g} N·m·s/rad (correction "
        f"{found.correction_n_m_s:+.4g} N·m·s/rad, {found.share:+.1%} of B44; Reynolds "
        f"{found.reynolds_model:.3g} model, {found.reynolds_ship:.3g} ship)"
    )
    return text, assumption_lines(friction.assumptions())
