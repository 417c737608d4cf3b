"""How the API's long calls tell their caller what they do: lines for the user and progress of tasks.

A notebook wants neither (the lines are kept on the result as ``notices``); the command line draws them
with rich (``cli.app.TerminalProgress``), or, when stderr is a pipe or a log file where a live bar draws
nothing, as plain lines (``Lines``). The API never imports rich: the caller gives a ``Progress``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from typing import Protocol

#: Moves a task on: ``update(done, total=None, description=None)`` (None leaves the total or the
#: description as it was; a description says what the task is at, such as the file being read).
Update = Callable[..., None]


class Progress(Protocol):
    """What a long call reports: one line for the user at a time, and tasks with a count of work done."""

    def line(self, text: str) -> None:
        """One line the user should read (what was read, what was decided)."""

    def task(self, description: str, total: int | None = None) -> AbstractContextManager[Update]:
        """A task under way while the context is open; ``total`` None: of unknown length."""


class Quiet:
    """The notebook's default: nothing shown (the results keep the lines as ``notices``)."""

    def line(self, text: str) -> None:
        pass

    @contextmanager
    def task(self, description: str, total: int | None = None) -> Iterator[Update]:
        yield lambda done, total=None, description=None: None


class Kept:
    """``progress`` as given, with every line also kept in ``lines`` (a result's ``notices``)."""

    def __init__(self, progress: Progress | None) -> None:
        self.progress: Progress = progress if progress is not None else Quiet()
        self.lines: list[str] = []

    def line(self, text: str) -> None:
        self.lines.append(text)
        self.progress.line(text)

    def task(self, description: str, total: int | None = None) -> AbstractContextManager[Update]:
        return self.progress.task(description, total)


#: How often ``Lines`` says where a task is: a long job in a log or a pipe is never silent for longer.
EVERY_S = 10.0


@dataclass
class _Task:
    """Where a task of ``Lines`` is, and when it last said so."""

    description: str
    total: int | None
    start: float
    said: float
    done: int = 0

    def where(self, now: float) -> str:
        count = f"{self.done}/{self.total}" if self.total is not None else str(self.done)
        return f"{self.description}: {count} after {now - self.start:.0f} s"


class Lines:
    """Progress as plain lines through ``write``, for a log or a pipe: each task says where it is at most
    every ``every_s`` seconds of ``clock`` (at its updates), and that it ended if it said anything."""

    def __init__(
        self,
        write: Callable[[str], None],
        every_s: float = EVERY_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.write, self.every_s, self.clock = write, every_s, clock

    def line(self, text: str) -> None:
        self.write(text)

    @contextmanager
    def task(self, description: str, total: int | None = None) -> Iterator[Update]:
        now = self.clock()
        task = _Task(description, total, now, now)

        def update(done: int, total: int | None = None, description: str | None = None) -> None:
            task.done = done
            task.total = task.total if total is None else total
            task.description = task.description if description is None else description
            now = self.clock()
            if now - task.said >= self.every_s:
                task.said = now
                self.write(task.where(now))

        yield update
        if task.said != task.start:  # a task that said where it was says that it ended
            self.write(task.where(self.clock()) + ", done")
