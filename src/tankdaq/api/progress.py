"""How the API's long calls tell their caller what they do: lines for the user and progress of tasks.

A notebook wants neither (the lines are kept on the result as ``notices``); the command line draws them
with rich (``cli.app.TerminalProgress``). The API never imports rich: the caller gives a ``Progress``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
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
