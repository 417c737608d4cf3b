"""Test conditions of decays (hull, draft, axis, speed): ``identify`` never pools two silently.

A hull at 1.1T has another inertia and stiffness than at T: one fit of both is a fit of neither. The
condition comes from the recording's metadata (``store.reader``: hull, draft), else from the file
name (``store.naming.parse_recording_name``, the one name grammar); the release angle is not part of
it (decays of one condition from several angles are what a joint fit is for, reference §4).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..config.hulls import format_draft, parse_draft
from ..records import DecayRun
from ..store.naming import parse_recording_name

UNKNOWN = "?"


@dataclass(frozen=True)
class Condition:
    """What a decay was tested at; ``?`` where neither the metadata nor the name says."""

    hull: str
    draft: str
    axis: str
    speed: str

    @property
    def label(self) -> str:
        known = [p for p in (self.hull, self.draft) if p != UNKNOWN]
        speed = [f"{self.speed} m/s"] if self.speed != UNKNOWN else []
        return " ".join([*known, self.axis, *speed]) if known else f"{self.axis} (condition not labelled)"

    def as_dict(self) -> dict[str, Any]:
        return {"hull": self.hull, "draft": self.draft, "axis": self.axis, "speed_m_s": self.speed}


def condition_of(run: DecayRun) -> Condition:
    """The run's condition from its metadata, else its file's name."""
    hull, draft, speed = run.meta.get("hull"), run.meta.get("draft"), run.meta.get("speed_m_s")
    if hull is None or draft is None:
        named = parse_recording_name(Path(str(run.meta.get("file", run.name))).name)
        if named is not None:
            hull, draft = hull or named.hull, named.draft if draft is None else draft
    return Condition(
        str(hull) if hull is not None else UNKNOWN,
        format_draft(parse_draft(draft) if isinstance(draft, str) else float(draft))
        if draft is not None
        else UNKNOWN,
        run.axis,
        f"{float(speed):g}" if speed is not None else UNKNOWN,
    )


def group_conditions(runs: Iterable[DecayRun]) -> dict[Condition, list[DecayRun]]:
    """Runs by condition, in first-seen order."""
    groups: dict[Condition, list[DecayRun]] = {}
    for run in runs:
        groups.setdefault(condition_of(run), []).append(run)
    return groups


def grouping_line(groups: dict[Condition, list[DecayRun]], joint: bool = False) -> str:
    """One line: how many conditions, which, and whether they were fitted apart or pooled."""
    described = "; ".join(f"{c.label} ({len(r)} run{'s' if len(r) > 1 else ''})" for c, r in groups.items())
    if joint:
        return f"pooled {len(groups)} conditions into one fit (--joint): {described}"
    return f"{len(groups)} conditions, one fit each: {described}"
