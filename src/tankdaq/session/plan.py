"""The test matrix as the guided session walks it: its conditions in order and the checks' tolerances.

Drafts are grouped (a ballast change is slow): every angle of a draft, then the next draft.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..config.hulls import format_draft, parse_draft
from ..config.plans import CampaignPlan, acceptance_values


@dataclass(frozen=True)
class Acceptance:
    """The checks' tolerances (the plan's ``[acceptance]`` table; degrees at this edge)."""

    angle_tolerance_deg: float = 1.0  # |release angle - nominal|
    level_tolerance_deg: float = 1.0  # |still-water angle| before the tilt (the model trimmed level)
    min_half_cycles: float = 5  # a decay shorter than this says little
    min_r2: float = 0.98  # the final fit's R² on the angle
    rate_limit_deg_s: float = 290.0  # |rate| at or above this: the gyro saturated (MTi-G: ±300 deg/s)
    repeat_tolerance: float = 0.2  # B_eq at the nominal angle vs the earlier repeats, relative
    period_tolerance: float = 0.03  # natural period vs the earlier repeats, relative
    max_flagged_samples: float = 0  # samples after the release the sensor flags (clipped): more, rejected

    @classmethod
    def from_plan(cls, table: dict[str, float], where: str) -> Acceptance:
        """The plan's tolerances, each known and in its range (``config.plans.ACCEPTANCE_RANGES``)."""
        return cls(**acceptance_values(table, f"{where}: [acceptance]"))


@dataclass(frozen=True)
class PlannedCondition:
    """One cell of the test matrix."""

    draft: str  # as people write it: 0.9T, T, 1.1T
    angle_deg: float

    @property
    def draft_factor(self) -> float:
        return parse_draft(self.draft)

    @property
    def label(self) -> str:
        return f"{self.draft} {self.angle_deg:g} deg"


def plan_conditions(plan: CampaignPlan) -> list[PlannedCondition]:
    """The conditions in the order they are run: every angle of a draft, then the next draft."""
    drafts = [format_draft(parse_draft(d)) for d in plan.drafts]
    return [PlannedCondition(d, float(a)) for d in drafts for a in plan.angles_deg]
