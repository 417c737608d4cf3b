"""Listeners of the pipeline's events (``acquire.events``): the printer of the lines a person reads, a
collector for tests and notebooks, and a JSON-lines stream for programs (``--events jsonl``).

Each is a ``Sink`` that overrides only ``on_event``: it rides along the record daemon's or replay's
pipeline like any other sink and never touches a decay.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from typing import IO, TypeVar

from .events import Event, legend
from .sinks import Sink

E = TypeVar("E", bound=Event)


class EventPrinter(Sink):
    """Each printed event as its line to ``write``; the words a line uses are explained once before it
    (``events.legend``). ``run_name`` names a run in the orchestrator's words (a guided session's
    "decay 5"); ``once``: a line already shown is not shown again (a session's device and viewer lines)."""

    def __init__(
        self,
        write: Callable[[str], None],
        run_name: Callable[[Event], str | None] = lambda _event: None,
        once: tuple[type[Event], ...] = (),
    ) -> None:
        self.write = write
        self.run_name = run_name
        self.once = once
        self._said: set[str] = set()

    def on_event(self, event: Event) -> None:
        if not event.printed:
            return
        line = event.line(self.run_name(event))
        if isinstance(event, self.once):
            if line in self._said:
                return
            self._said.add(line)
        explained = legend(event)
        if explained is not None and explained not in self._said:
            self._said.add(explained)
            self.write(explained)
        self.write(line)


class EventLog(Sink):
    """Every event, in order (``events``), and ``wait_for`` a kind of event from another thread: what a
    test steers the pipeline by, and a notebook's record of a session."""

    def __init__(self, react: Callable[[Event], None] = lambda _event: None) -> None:
        self.events: list[Event] = []
        self.react = react  # called with each event as it comes (stop the daemon at a release...)
        self._arrived = threading.Condition()

    def on_event(self, event: Event) -> None:
        with self._arrived:
            self.events.append(event)
            self._arrived.notify_all()
        self.react(event)

    def of(self, kind: type[E]) -> list[E]:
        """The events of one type, in order."""
        return [event for event in list(self.events) if isinstance(event, kind)]

    def wait_for(self, kind: type[E], timeout_s: float) -> E | None:
        """The first event of ``kind``, waiting up to ``timeout_s`` for it; None when none came."""
        with self._arrived:
            self._arrived.wait_for(lambda: bool(self.of(kind)), timeout_s)
        found = self.of(kind)
        return found[0] if found else None


class EventStream(Sink):
    """Each event as one JSON object per line (``Event.record()``), flushed as it comes: what a program
    reads instead of the printed lines (``record --events jsonl``)."""

    def __init__(self, out: IO[str]) -> None:
        self.out = out
        self._lock = threading.Lock()  # the view's notes come from its own thread

    def on_event(self, event: Event) -> None:
        if not event.streamed:  # kept with the decay only (``KeptNote``)
            return
        text = json.dumps(event.record(), default=str)
        with self._lock:
            self.out.write(text + "\n")
            self.out.flush()
