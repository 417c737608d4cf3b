"""The operator's side of a guided session: the questions asked, who answers them, the progress line.

The operator is an ``Operator``: ``ask(Question) -> answer``. ``ScriptedOrTerminalOperator`` answers
from a responses file first, then ``--yes`` (the default), then the terminal; tests script it the same way.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from ..config import validation
from ..errors import InputError
from .plan import PlannedCondition

#: rejected decays of one condition after which the default answer is to skip it, not to repeat it
#: (``--yes`` answers the default: a condition that keeps failing cannot loop forever)
MAX_REJECTED = 3


@dataclass(frozen=True)
class Question:
    """A prompt: ``kind`` (draft, verdict), the text, the keys understood and the default (Enter)."""

    kind: str
    text: str
    choices: dict[str, str]
    default: str


class Operator(Protocol):
    def ask(self, question: Question) -> str:
        """The answer: a key of ``question.choices`` ("" = the default), or ``n <text>`` for a note."""
        ...


@dataclass
class SessionProgress:
    """What the progress line shows."""

    condition: PlannedCondition | None
    repeat: int
    done: int
    total: int
    decays: int
    elapsed_s: float
    left_s: float | None

    def line(self) -> str:
        left = "" if self.left_s is None else f", about {_minutes(self.left_s)} left"
        where = f"{self.condition.label} repeat {self.repeat}" if self.condition else "done"
        kept = f"{self.done}/{self.total} decays kept, {self.decays} recorded"
        return f"{where} | {kept} | {_minutes(self.elapsed_s)} spent{left}"


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.0f} min" if seconds >= 90 else f"{seconds:.0f} s"


def keys_line(question: Question) -> str:
    """The keys a question understands (Enter = its default), and the note."""
    return (
        ", ".join(f"{'Enter' if k == question.default else k}={v}" for k, v in question.choices.items())
        + ", n TEXT=note"
    )


def describe_question(question: Question) -> str:
    """The prompt line: text, then the keys (Enter = the default)."""
    return f"{question.text} [{keys_line(question)}]"


def draft_question(draft: str, angles_deg: list[float]) -> Question:
    """Set the draft and say when (its angles come next); Enter = ready, s = skip the draft."""
    angles = ", ".join(f"{a:g}" for a in angles_deg)
    return Question(
        "draft",
        f"Set draft {draft} and trim the model level (angles {angles} deg next); "
        "leave it at rest for the level check",
        {"": "ready", "s": f"skip draft {draft}"},
        "",
    )


def verdict_question(decay: int, condition: PlannedCondition, failed: bool, rejected: int) -> Question:
    """Keep the decay? One that failed a check defaults to a repeat, or, once the condition's
    ``MAX_REJECTED``-th decay failed (``rejected`` before this one), to skipping the condition."""
    if not failed:
        return Question(
            "verdict",
            f"Keep decay {decay} ({condition.label})?",
            {"a": "accept", "r": "reject and repeat", "s": "reject and skip the condition"},
            "a",
        )
    give_up = rejected + 1 >= MAX_REJECTED
    return Question(
        "verdict",
        f"Decay {decay} ({condition.label}) failed a check"
        + (
            f"; {rejected + 1} decays of this condition failed (limit {MAX_REJECTED}): skip it?"
            if give_up
            else ": repeat it?"
        ),
        {"r": "reject and repeat", "a": "accept anyway", "s": "reject and skip the condition"},
        "s" if give_up else "r",
    )


class ScriptedOrTerminalOperator:
    """Answers from the responses file first, then --yes (the default), then the terminal.

    ``say`` shows each question and answer; ``read_line(prompt)`` reads one from the terminal."""

    def __init__(
        self, responses: list[str], yes: bool, say: Callable[[str], None], read_line: Callable[[str], str]
    ) -> None:
        self.responses = responses
        self.yes = yes
        self.say = say
        self.read_line = read_line

    def ask(self, question: Question) -> str:
        self.say(f"? {describe_question(question)}")
        if self.responses:
            answer = self.responses.pop(0)
            self.say(f"> {answer or '(Enter)'}")
            return answer
        if self.yes:
            self.say("> (Enter)")
            return ""
        if not sys.stdin.isatty():
            raise InputError("a question needs an answer and none is left: give --yes or --responses FILE")
        return self.read_line("> ")


def read_responses(path: Path | None) -> list[str]:
    """One answer per line (an empty line is Enter); lines starting with # are comments."""
    if path is None:
        return []
    validation.input_file(path, what="responses file")
    return [line.rstrip("\n") for line in path.read_text().splitlines() if not line.startswith("#")]
