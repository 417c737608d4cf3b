"""The signals that stop a recording (Ctrl-C, SIGTERM, SIGHUP) and how the recorder hears them: the
decay under way is closed as a complete file, never cut mid-write."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from enum import Enum

#: What stops a recording the way Ctrl-C does: the decay under way closes as a complete file.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Phase(Enum):
    """Where the recorder is, which says what a first stop signal does there."""

    STARTING = "starting"  # preparing the kernels, opening the device, waiting for it: raise at once
    FEEDING = "feeding"  # in the read loop: the reader stops, the blocks it read are fed, then it ends
    BETWEEN_STEPS = "between steps"  # a guided session between its steps: the next step reads ``stop``
    CLOSING = "closing"  # the files are being closed: nothing may cut them


class SignalStop:
    """Ctrl-C, SIGTERM and SIGHUP stop the recorder, the open decay closed as a complete file.

    What the first signal does depends on the ``phase`` (``Phase``): it always sets ``stop``, and only
    while ``STARTING`` (nothing recorded) does it raise KeyboardInterrupt; in the read loop the loop ends
    after the blocks read are fed (an exception raised into the middle of a write could leave the file
    without its footer). Later signals do nothing more: they wait for the files to close, and the closing
    is bounded (the final fit at most ``FINAL_FIT_WAIT_S`` of computing, the view 15 s). ``stop()`` asks
    the same without a signal (a callback, another thread).
    """

    def __init__(self) -> None:
        self.stop = threading.Event()
        self.stopped_by: str | None = None  # the first signal's name
        self.phase = Phase.STARTING

    def __call__(self, signum: int, _frame: object) -> None:
        first = self.stopped_by is None
        if first:
            self.stopped_by = signal.Signals(signum).name
        self.stop.set()
        if first and self.phase is Phase.STARTING:  # a second one never cuts a stop
            raise KeyboardInterrupt

    @property
    def asked(self) -> bool:
        """Whether a stop was asked (a signal, or ``stop.set()``)."""
        return self.stop.is_set()

    @contextlib.contextmanager
    def during(self, phase: Phase) -> Iterator[None]:
        """``phase`` while the block runs, the one before restored after."""
        before, self.phase = self.phase, phase
        try:
            yield
        finally:
            self.phase = before

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        """The handler on every stop signal while the block runs (only the main thread can)."""
        previous: dict[int, object] = {}
        try:
            for signum in STOP_SIGNALS:
                previous[signum] = signal.signal(signum, self)
        except ValueError:  # not the main thread (tests): leave signals alone
            pass
        try:
            yield
        finally:
            for number, handler in previous.items():
                signal.signal(number, handler)  # type: ignore[arg-type]
