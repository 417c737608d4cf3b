"""What a session finds in its folder as it opens that its log does not say, logged so nothing is lost.

A recording the log never heard of (the session died mid-decay) is adopted: logged as a decay and
rejected. A logged decay whose recording is gone since is rejected (``missing``), so its condition is
recorded again and the report covers only files that exist.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ...config import format_draft, parse_draft
from .journal import SessionLog
from .plan import Condition
from .state import SessionState


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


def adopt_orphans(log: SessionLog, state: SessionState, on_line: Callable[[str], None]) -> None:
    """Recordings in the folder the log never heard of (the session died mid-decay): logged, rejected."""
    known = {r.file for r in state.runs}
    decay = state.next_decay - 1
    for path in sorted(log.path.parent.glob("*.mcap")):
        if path.name in known:
            continue
        decay += 1
        condition = _condition_of(path) or state.next_condition() or state.conditions[-1]
        reason = "the session stopped during this decay (recovered from the folder)"
        log.append("run", decay=decay, draft=condition.draft, angle_deg=condition.angle_deg,
                   file=path.name, reasons=[reason], measured={})  # fmt: skip
        log.append("verdict", decay=decay, verdict="rejected", action="recovered")
        on_line(f"decay {decay}: {path.name} is not in the log (cut by a stop); kept, marked rejected")


def _condition_of(path: Path) -> Condition | None:
    """The condition a recording's metadata names (None: a file cut before its metadata)."""
    from ...store.reader import read_recording

    try:
        meta = read_recording(path).metadata
        return Condition(format_draft(parse_draft(str(meta["draft"]))), float(meta["angle_nominal_deg"]))
    except Exception:  # a file cut before its metadata: the condition under way is the best guess
        return None
