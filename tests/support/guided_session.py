"""What the guided session's tests share: the two-draft plan and an operator who presses Enter; a plan of
one decay repeated and an operator who repeats it, then skips; a signal sent to a ``tankdaq session``
process once it has reached a given point."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable
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


def signal_when(
    proc: subprocess.Popen[str], ready: Callable[[], bool], signum: int, what: str, wait_s: float = 120.0
) -> str:
    """Send ``signum`` to the session process once ``ready()`` holds (polled, bounded by ``wait_s``: the
    assertion says ``what`` it waited for) and wait for it to end; its stderr. A process that fails or
    hangs is killed before the test goes on."""
    try:
        deadline = time.monotonic() + wait_s
        while not ready():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, what
            time.sleep(0.02)  # polling the session's files: a real condition, bounded
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return err
