"""The signals that stop a recording (Ctrl-C, SIGTERM, SIGHUP) and how the record daemon hears them: the
decay under way is closed as a complete file, never cut mid-write."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

#: What stops a recording the way Ctrl-C does: the decay under way closes as a complete file.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class SignalStop:
    """Ctrl-C, SIGTERM and SIGHUP stop the daemon, the open decay closed as a complete file.

    Inside the read loop a signal only asks the loop to end: the reader stops after its current
    read, the blocks it read are fed, then the files close (an exception raised into the middle of a
    write could leave the file without its footer); ``deferred`` (a guided session between its
    steps): it only sets ``stop``, which the session's next step reads; anywhere else
    (preparing the kernels, opening the device, waiting for it to come back) it raises
    KeyboardInterrupt at once. Only the first signal does anything: later ones wait for the files
    to close, and the closing is bounded (the final fit at most ``FINAL_FIT_WAIT_S`` of computing,
    the view 15 s).
    """

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop
        self.stopped_by: str | None = None  # the first signal's name
        self.in_loop = False
        self.closing = False
        self.deferred = False

    def __call__(self, signum: int, _frame: object) -> None:
        first = self.stopped_by is None
        if first:
            self.stopped_by = signal.Signals(signum).name
        self.stop.set()
        if first and not (self.in_loop or self.closing or self.deferred):  # a second one never cuts a stop
            raise KeyboardInterrupt

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
