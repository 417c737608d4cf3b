"""What a session finds in its folder that its log does not say, logged so nothing is lost.

A recording the log never heard of is adopted: logged as a decay and rejected. As the session opens, it
is one the session died while recording (``STOPPED_DURING``); while it runs, one released between decays,
when no decay was asked for (``RELEASED_BETWEEN``: the operator moved the model during a question). A
logged decay whose recording is gone since is rejected (``missing``), so its condition is recorded again
and the report covers only files that exist.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..config.hulls import format_draft, parse_draft
from .journal import SessionLog
from .plan import PlannedCondition
from .state import SessionState


@dataclass(frozen=True)
class Orphan:
    """Why a recording is not in the log: the reason logged, the verdict's action, the line's words."""

    reason: str
    action: str
    said: str


STOPPED_DURING = Orphan(
    "the session stopped during this decay (recovered from the folder)",
    "recovered",
    "is not in the log (cut by a stop)",
)
RELEASED_BETWEEN = Orphan(
    "released between decays, when no decay was asked for (recorded, never lost)",
    "between decays",
    "was released between decays, when no decay was asked for",
)


def mark_missing(log: SessionLog, state: SessionState, on_line: Callable[[str], None]) -> None:
    """Decays whose file is gone from the folder since: rejected, so their condition is recorded
    again and the report covers only files that exist."""
    folder = log.path.parent
    for run in state.runs:
        if run.verdict == "rejected" or (folder / run.file).is_file():
            continue
        reason = f"{run.file} is gone from {folder}"
        log.append("verdict", decay=run.decay, verdict="rejected", action="missing", reasons=[reason])
        on_line(f"decay {run.decay}: {reason}; marked rejected, {run.condition.label} is recorded again")


def adopt_orphans(
    log: SessionLog, state: SessionState, on_line: Callable[[str], None], why: Orphan = STOPPED_DURING
) -> None:
    """Recordings in the folder the log never heard of (``why``: how it came to be): logged, rejected."""
    known = {r.file for r in state.runs}
    decay = state.next_decay - 1
    for path in sorted(log.path.parent.glob("*.mcap")):
        if path.name in known:
            continue
        decay += 1
        condition = _condition_of(path) or state.next_condition() or state.conditions[-1]
        log.append("run", decay=decay, draft=condition.draft, angle_deg=condition.angle_deg,
                   file=path.name, reasons=[why.reason], measured={})  # fmt: skip
        log.append("verdict", decay=decay, verdict="rejected", action=why.action)
        on_line(f"decay {decay}: {path.name} {why.said}; kept, marked rejected")


def _condition_of(path: Path) -> PlannedCondition | None:
    """The condition a recording's metadata names (None: a file cut before its metadata)."""
    from ..store.reader import read_recording

    try:
        meta = read_recording(path).metadata
        return PlannedCondition(
            format_draft(parse_draft(str(meta["draft"]))), float(meta["angle_nominal_deg"])
        )
    except Exception:  # a file cut before its metadata: the condition under way is the best guess
        return None
