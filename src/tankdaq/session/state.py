"""Where a guided session stands, derived from its log alone (``SessionState.from_log``).

Nothing else holds state: a resume after Ctrl-C, a crash or a power cut reads the log again and
continues exactly where it stopped. A record that contradicts the ones before it is left out and listed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from .checks import usable_measured
from .journal import LOG_NAME
from .plan import PlannedCondition


class LogKind(StrEnum):
    """The kinds of record a session log holds (each record's ``type``) that move its state."""

    RUN = "run"  # a decay recorded, measured and checked
    VERDICT = "verdict"  # the operator's (or the recovery's) verdict on a decay
    SKIP = "skip"  # a condition skipped
    DRAFT = "draft"  # the draft set and its still water level
    REPORT = "report"  # the report written
    START = "start"  # the session (re)started


@dataclass
class RunEntry:
    """A decay as the log knows it."""

    decay: int
    condition: PlannedCondition
    file: str
    reasons: list[str]
    measured: dict[str, Any]
    verdict: str | None = None  # accepted, rejected; None: not judged yet


@dataclass
class SessionState:
    """Where the session stands, from its log alone."""

    conditions: list[PlannedCondition]
    repeats: int
    runs: list[RunEntry] = field(default_factory=list)
    skipped: set[PlannedCondition] = field(default_factory=set)
    draft_ready: str | None = None  # the draft the operator last confirmed
    report: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)  # records left out, one line each

    @classmethod
    def from_log(
        cls, records: list[dict[str, Any]], conditions: list[PlannedCondition], repeats: int
    ) -> SessionState:
        """The state the records say (each already checked by ``journal.record_problem``); a record
        that contradicts the ones before it is left out and listed in ``problems``."""
        state = cls(conditions, repeats)
        by_decay: dict[int, RunEntry] = {}
        for number, r in enumerate(records, 1):
            why = state._apply(r, by_decay)
            if why:
                state.problems.append(f"{LOG_NAME} record {number} ({r.get('type')}) skipped: {why}")
        return state

    def _apply(self, r: dict[str, Any], by_decay: dict[int, RunEntry]) -> str | None:
        kind = r.get("type")
        if kind == LogKind.RUN:
            if r["decay"] in by_decay:
                return f"decay {r['decay']} was logged before"
            if r["measured"] and not usable_measured(r["measured"]):
                return "its measured values are incomplete"
            entry = RunEntry(
                r["decay"],
                PlannedCondition(r["draft"], float(r["angle_deg"])),
                r["file"],
                r["reasons"],
                r["measured"],
            )
            by_decay[entry.decay] = entry
            self.runs.append(entry)
        elif kind == LogKind.VERDICT:
            judged = by_decay.get(r["decay"])
            if judged is None:
                return f"no decay {r['decay']} was logged"
            if r["verdict"] == "accepted" and not judged.measured:
                return f"decay {judged.decay} has nothing measured to accept"
            judged.verdict = r["verdict"]
            self.report = []  # a verdict after the report: the report no longer covers the accepted decays
        elif kind == LogKind.SKIP:
            self.skipped.add(PlannedCondition(r["draft"], float(r["angle_deg"])))
        elif kind == LogKind.DRAFT:
            self.draft_ready = r["draft"]
        elif kind == LogKind.REPORT:
            self.report = list(r["files"])
        elif kind == LogKind.START:
            self.draft_ready = None  # after a restart the level is checked again
        return None

    def accepted(self, condition: PlannedCondition) -> list[RunEntry]:
        return [r for r in self.runs if r.condition == condition and r.verdict == "accepted"]

    def status(self, condition: PlannedCondition) -> str:
        """to do, under way, rejected (its last decay: to be repeated), accepted or skipped."""
        if condition in self.skipped:
            return "skipped"
        if len(self.accepted(condition)) >= self.repeats:
            return "accepted"
        mine = [r for r in self.runs if r.condition == condition]
        if not mine:
            return "to do"
        return "rejected" if mine[-1].verdict == "rejected" else "under way"

    def next_condition(self) -> PlannedCondition | None:
        return next((c for c in self.conditions if self.status(c) not in ("accepted", "skipped")), None)

    def unjudged(self) -> RunEntry | None:
        return next((r for r in self.runs if r.verdict is None), None)

    @property
    def decays(self) -> int:
        return len(self.runs)

    @property
    def next_decay(self) -> int:
        """The number of the next decay (after the highest logged: a skipped record leaves a gap)."""
        return max((r.decay for r in self.runs), default=0) + 1

    def runs_left(self) -> int:
        return sum(
            max(self.repeats - len(self.accepted(c)), 0) for c in self.conditions if c not in self.skipped
        )
