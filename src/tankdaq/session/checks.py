"""The acceptance checks of a decay: pure functions of what was measured (``measure``) and the plan.

A decay that fails one is flagged with one line per reason and the operator asked to repeat it; a
final fit that physics says is implausible is a reason too (never accepted silently).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..acquire.events import ModelMoved, MovedKind
from ..records import DecayEnd
from .plan import Acceptance, PlannedCondition

#: the still water moves less than this (standard deviation, deg) when the model is at rest
STILL_SD_DEG = 0.3


@dataclass
class Measured:
    """What the checks look at in one recorded decay (degrees, SI otherwise)."""

    angle_deg: float
    still_water_deg: float
    ended: DecayEnd
    half_cycles: int = 0
    r2_angle: float = math.nan
    coefficients: dict[str, float] = field(default_factory=dict)
    natural_period_s: float = math.nan
    b_eq_per_s: float = math.nan  # at the nominal angle
    max_rate_deg_s: float = math.nan
    free_end: str = ""  # how the free decay ends (``ident.free_decay``): "excitation" = pushed again
    free_end_reason: str = ""
    fit_error: str = ""
    fit_warnings: list[str] = field(default_factory=list)  # the final fit's implausibilities
    flagged_samples: int = 0  # after the release, flagged by the sensor (clipping, orientation not valid)
    flagged_why: str = ""  # the one line the recording's reader gives them

    @classmethod
    def from_log(cls, values: dict[str, Any]) -> Measured:
        """A decay's measurements as the session log keeps them (``usable_measured`` says they are)."""
        values = _logged(values)
        values["ended"] = DecayEnd.of_settle_reason(values["ended"]) or DecayEnd.STOPPED
        return cls(**values)


def _logged(values: dict[str, Any]) -> dict[str, Any]:
    """A logged ``measured`` under today's keys: a log written before ``ended`` names the decay's end by its
    ``settle_reason`` (``amplitude``, ``note``...: ``DecayEnd.of_settle_reason`` reads both)."""
    values = dict(values)
    if "ended" not in values and "settle_reason" in values:
        values["ended"] = values.pop("settle_reason")
    return values


def check_decay(
    measured: Measured, condition: PlannedCondition, acceptance: Acceptance, earlier: list[Measured]
) -> list[str]:
    """Why this decay should be repeated (empty: it passes). ``earlier``: the condition's accepted repeats."""
    a = acceptance
    reasons = []
    if not measured.ended.whole:
        reasons.append(f"cut short ({measured.ended.words})")
    off = measured.angle_deg - condition.angle_deg
    if abs(off) > a.angle_tolerance_deg:
        reasons.append(
            f"released at {measured.angle_deg:.1f} deg, {off:+.1f} deg from the nominal "
            f"{condition.angle_deg:g} "
            f"(tolerance {a.angle_tolerance_deg:g})"
        )
    if abs(measured.still_water_deg) > a.level_tolerance_deg:
        reasons.append(
            f"not level: still water at {measured.still_water_deg:+.2f} deg "
            f"(tolerance {a.level_tolerance_deg:g}); re-trim"
        )
    if measured.free_end == "excitation":
        reasons.append(f"release not clean: {measured.free_end_reason}")
    if measured.max_rate_deg_s >= a.rate_limit_deg_s:
        reasons.append(f"rate saturated: {measured.max_rate_deg_s:.0f} deg/s (limit {a.rate_limit_deg_s:g})")
    if measured.flagged_samples > a.max_flagged_samples:
        reasons.append(
            f"clipped: {measured.flagged_why or f'{measured.flagged_samples} samples flagged'} "
            f"(max_flagged_samples {a.max_flagged_samples:g}); repeat at a smaller angle"
        )
    if measured.fit_error:
        reasons.append(f"no fit: {measured.fit_error}")
        return reasons
    if measured.half_cycles < a.min_half_cycles:
        reasons.append(f"too short: {measured.half_cycles} half-cycles (at least {a.min_half_cycles:g})")
    if not measured.r2_angle >= a.min_r2:
        reasons.append(f"poor fit: R² {measured.r2_angle:.4f} (at least {a.min_r2:g})")
    reasons += [f"fit: {line}" for line in measured.fit_warnings]  # never accepted silently
    if earlier:
        reasons += _repeat_reasons(measured, earlier, a)
    return reasons


def watch_reasons(stood: list[ModelMoved]) -> list[str]:
    """Why a decay should be repeated for what the watch saw standing at its release (``guided.watch``):
    a bump the model had not settled from, a still water creeping, a drifted level (off level is the
    still-water check's)."""
    reasons = []
    for moved in stood:
        if moved.kind == MovedKind.BUMP:
            reasons.append(
                f"released after a bump the model had not settled from (spread {moved.spread_deg:.2f} deg, "
                f"rate {moved.rate_deg_s:.1f} deg/s rms at t = {moved.t_s:.1f} s); wait for still water"
            )
        elif moved.kind == MovedKind.TREND:
            reasons.append(
                f"released while the still water crept at {moved.slope_deg_min:+.1f} deg/min "
                f"(at {moved.angle_deg:+.2f} deg, t = {moved.t_s:.1f} s); find why (water inside, a weight "
                "that moved) and re-trim"
            )
        elif moved.kind == MovedKind.DRIFT:
            reasons.append(
                f"released from a drifted level: still water at {moved.angle_deg:+.2f} deg, "
                f"{moved.angle_deg - moved.reference_deg:+.2f} deg from the {moved.reference_deg:+.2f} "
                f"measured when the draft was set (tolerance {moved.limit_deg:g}); re-trim"
            )
    return reasons


def is_level(mean_deg: float, sd_deg: float, acceptance: Acceptance) -> bool:
    """Whether the still water before a draft's first decay is level and at rest."""
    return abs(mean_deg) <= acceptance.level_tolerance_deg and sd_deg <= STILL_SD_DEG


def usable_measured(measured: dict[str, Any]) -> bool:
    """Whether a logged ``measured`` makes a ``Measured`` (the checks of later repeats read it)."""
    measured = _logged(measured)
    if DecayEnd.of_settle_reason(measured.get("ended")) is None:
        return False
    kinds = {
        "DecayEnd": (str,),
        "float": (int, float),
        "int": (int, float),
        "str": (str,),
        "dict[str, float]": (dict,),
        "list[str]": (list,),
    }
    for f in dataclasses.fields(Measured):
        value = measured.get(f.name)
        if (
            f.name not in measured
            and f.default is dataclasses.MISSING
            and f.default_factory is dataclasses.MISSING
        ):
            return False
        if f.name in measured and (isinstance(value, bool) or not isinstance(value, kinds[str(f.type)])):
            return False
    coefficients = measured.get("coefficients", {})
    warnings = measured.get("fit_warnings", [])
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in coefficients.values()) and all(
        isinstance(w, str) for w in warnings
    )


def _repeat_reasons(measured: Measured, earlier: list[Measured], a: Acceptance) -> list[str]:
    reasons = []
    b_ref = float(np.mean([m.b_eq_per_s for m in earlier]))
    t_ref = float(np.mean([m.natural_period_s for m in earlier]))
    if abs(measured.b_eq_per_s - b_ref) > a.repeat_tolerance * abs(b_ref):
        reasons.append(
            f"not a repeat: B_eq {measured.b_eq_per_s:.4g} 1/s vs {b_ref:.4g} of the earlier repeats "
            f"(tolerance {a.repeat_tolerance:.0%})"
        )
    if abs(measured.natural_period_s - t_ref) > a.period_tolerance * t_ref:
        reasons.append(
            f"not a repeat: period {measured.natural_period_s:.3f} s vs {t_ref:.3f} s of the earlier repeats "
            f"(tolerance {a.period_tolerance:.0%})"
        )
    return reasons
