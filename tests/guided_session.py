"""What the guided session's tests share: the two-draft plan and an operator who presses Enter; a plan of
one decay repeated and an operator who repeats it, then skips."""

from __future__ import annotations

from typing import Any

#: 2 drafts x 2 angles x 2 repeats of the swath in roll: eight decays, a draft change between them.
TWO_DRAFT_PLAN = """description = "2 drafts x 2 angles x 2 repeats"
hulls = ["swath"]
axis = "roll"
drafts = ["T", "1.1T"]
angles_deg = [10.0, 15.0]
repeats = 2
[acceptance]
angle_tolerance_deg = 1.5
"""


class Enter:
    """An operator who presses Enter (every default) a bounded number of times, then walks away."""

    def __init__(self, limit: int = 6) -> None:
        self.limit = limit
        self.asked: list[str] = []

    def ask(self, question: Any) -> str:
        self.asked.append(question.kind)
        if len(self.asked) > self.limit:
            raise KeyboardInterrupt
        return ""


#: one condition of the swath in roll, twice: two decays on one draft.
ONE_CONDITION_TWICE = """hulls = ["swath"]
axis = "roll"
drafts = ["T"]
angles_deg = [10.0]
repeats = 2
[acceptance]
angle_tolerance_deg = 1.5
"""


class Repeating:
    """Says the draft is ready, repeats the first decay and skips the condition at the second (nothing
    accepted: no report to fit), and keeps each question's kind and default."""

    def __init__(self) -> None:
        self.asked: list[tuple[str, str]] = []
        self.verdicts = ["r", "s"]

    def ask(self, question: Any) -> str:
        self.asked.append((question.kind, question.default))
        assert len(self.asked) < 10, "the session should have ended"
        return self.verdicts.pop(0) if question.kind == "verdict" else ""
