"""Test matrices (campaign plans): which hulls, axis, drafts, angles and repeats a campaign or a guided
session covers, and the tolerances a session checks each decay against.

A plan file is read like a hull file (``config.rules``): every key known (the nearest suggested), every
value in its range, one line for anything else, before a device opens (docs/session.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import ConfigError, InputError
from .hulls import config_dir, parse_draft
from .rules import (
    MAX_RELEASE_ANGLE_DEG,
    listed,
    number,
    read_toml,
    refuse_unknown,
    shown,
    table,
    text,
    whole_number,
)


@dataclass
class CampaignPlan:
    """A test matrix: which hulls, axis, drafts and initial angles a campaign covers.

    A guided session (``tankdaq session``) also reads ``repeats`` (decays kept per condition) and the
    ``[acceptance]`` table (tolerances of its checks, ``session.plan.Acceptance``). The
    conditions run in the order written: all angles of the first draft, then the next draft.
    """

    name: str
    description: str
    hulls: list[str]
    axis: str
    drafts: list[str]
    angles_deg: list[float]
    repeats: int = 1
    acceptance: dict[str, float] = field(default_factory=dict)


#: The keys of a plan file (docs/session.md).
PLAN_KEYS = ("description", "hulls", "axis", "drafts", "angles_deg", "repeats", "acceptance")
#: The axes a plan's decays are on (a session needs to know which one: no ``auto``).
PLAN_AXES = ("roll", "pitch")
#: Decays kept per condition, at the most (the seeds' labs ran three).
MAX_REPEATS = 100
#: ``[acceptance]`` tolerances and their ranges (above the first, at most the second): a tolerance at or
#: beyond these could never be met (an R² of 1) or would pass anything, and ``--yes`` would repeat for ever.
ACCEPTANCE_RANGES: dict[str, tuple[float, float]] = {
    "angle_tolerance_deg": (0.0, 10.0),
    "level_tolerance_deg": (0.0, 10.0),
    "min_half_cycles": (0.0, 100.0),
    "min_r2": (0.0, 0.9999),
    "rate_limit_deg_s": (0.0, 2000.0),
    "repeat_tolerance": (0.0, 10.0),
    "period_tolerance": (0.0, 1.0),
    "max_flagged_samples": (0.0, 1e6),
}


def list_campaign_plans() -> list[str]:
    """Names of the test matrices in configs/campaigns."""
    return sorted(p.stem for p in (config_dir() / "campaigns").glob("*.toml"))


def load_campaign_plan(name: str) -> CampaignPlan:
    """Load ``configs/campaigns/<name>.toml``, or a plan file given by path; an unknown name lists the
    known ones."""
    given = Path(name)
    path = given if given.suffix == ".toml" else config_dir() / "campaigns" / f"{name}.toml"
    if not path.is_file():
        raise InputError(
            f"unknown campaign plan {name!r}; known: {', '.join(list_campaign_plans()) or 'none'} "
            "(or give a .toml file)"
        )
    data = read_toml(path)
    where = str(path)
    refuse_unknown(data, PLAN_KEYS, where)
    missing = [key for key in ("hulls", "axis", "drafts", "angles_deg") if key not in data]
    if missing:
        raise ConfigError(f"{path}: needs {', '.join(missing)} (see docs/session.md for a plan's keys)")
    axis = data["axis"]
    if axis not in PLAN_AXES:
        raise ConfigError(f"{path}: axis must be one of {', '.join(PLAN_AXES)}, not {shown(axis)}")
    return CampaignPlan(
        name=path.stem,
        description=text(data, "description", where),
        hulls=[
            _plan_text(h, f"{path}: hulls[{i}]")
            for i, h in enumerate(listed(data["hulls"], f"{path}: hulls", "hull names", '["swath"]'))
        ],
        axis=axis,
        drafts=_plan_drafts(listed(data["drafts"], f"{path}: drafts", "drafts", '["T", "1.1T"]'), path),
        angles_deg=[
            number(a, f"{path}: angles_deg[{i}]", 0.0, MAX_RELEASE_ANGLE_DEG)
            for i, a in enumerate(
                listed(data["angles_deg"], f"{path}: angles_deg", "angles in degrees", "[10.0, 15.0]")
            )
        ],
        repeats=whole_number(data.get("repeats", 1), f"{path}: repeats", 1, MAX_REPEATS),
        acceptance=acceptance_values(table(data, "acceptance", where), f"{path}: [acceptance]"),
    )


def _plan_text(value: object, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{where} must be a name in quotes, not {shown(value)}")
    return value


def _plan_drafts(drafts: list[Any], path: Path) -> list[str]:
    """The drafts as written, each understood and none twice (``T`` and ``1.0T`` are one draft)."""
    seen: dict[float, str] = {}
    for i, draft in enumerate(drafts):
        factor = parse_draft(_plan_text(draft, f"{path}: drafts[{i}]"))
        if factor in seen:
            raise ConfigError(f"{path}: drafts {seen[factor]!r} and {draft!r} are the same draft; keep one")
        seen[factor] = draft
    return list(seen.values())


def acceptance_values(values: dict[str, Any], where: str) -> dict[str, float]:
    """A plan's ``[acceptance]`` tolerances: known keys (the nearest suggested), each in its range."""
    refuse_unknown(values, ACCEPTANCE_RANGES, where)
    return {key: number(v, f"{where} {key}", *ACCEPTANCE_RANGES[key]) for key, v in values.items()}
