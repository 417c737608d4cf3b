"""The recorder held open for a whole guided session: the device opened and configured once (one
handshake), streaming until the session ends.

``SessionStream`` composes a ``Recorder`` (``acquire.recorder``), as ``record`` does, and feeds it step
by step: ``stream_until`` feeds the stream until the session's condition holds (the still water measured,
the next decay settled), ``stream_during`` feeds it while the operator is asked a question (the asking on
a thread of its own: a long pause piles nothing up), and ``retarget`` sets the next decay's condition
(draft, nominal angle, note) between decays. Between steps the reading thread reads on and its blocks
wait in its queue for the next step (a moment: the session's own work): nothing the device sends is
skipped. The signal handlers are installed for the whole session: a Ctrl-C, SIGTERM or SIGHUP in a step
(a question included) closes the decay under way complete and ends the step with the typed ``Stopped``
event; one between steps ends the next step at once the same way.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future
from typing import TypeVar

from ..records import DecayEnd
from .events import Event, Stopped, Stopping
from .recorder import Recorder, RecordSettings
from .signals import Phase, SignalStop
from .sinks import Sink

T = TypeVar("T")

#: The name of the thread that waits for the operator's answer while the session's thread feeds the stream.
ASK_THREAD = "tankdaq-ask"


class SessionStream:
    """``with stream.streaming():`` the device open; ``stream_until`` and ``retarget`` inside it."""

    def __init__(self, settings: RecordSettings, sinks: Sequence[Sink] = ()) -> None:
        self.signals = SignalStop()
        self.recorder = Recorder(settings, sinks=sinks, stop=self.signals)

    def emit(self, event: Event) -> None:
        """An event for every listener of the stream (``Recorder.emit``)."""
        self.recorder.emit(event)

    @property
    def stopped_by(self) -> str | None:
        """The signal that stopped the stream, None while none has."""
        return self.signals.stopped_by

    @contextlib.contextmanager
    def streaming(self) -> Iterator[SessionStream]:
        """Open the device and build the pipeline; at the end (normal, an error, a stop) feed what was
        read, close the decay under way complete, the sinks and the device. The stop signals are the
        stream's all along: while the device opens a signal raises KeyboardInterrupt (nothing recorded
        yet), between steps it is kept for the next step, which then ends with ``Stopped``."""
        ended = DecayEnd.STOPPED  # a decay under way at the session's end was stopped, or cut by an error
        with self.signals.installed():
            opened = False
            try:
                self.recorder.open()
                opened = True
                with self.signals.during(Phase.BETWEEN_STEPS):
                    yield self
            except Exception:
                ended = DecayEnd.ERROR
                raise
            finally:
                self.recorder.close(ended, feed_read=opened)

    def stream_until(self, until: Callable[[], bool]) -> Stopped | None:
        """Feed the stream until ``until()`` holds (returns None), or until a signal stops it: the decay
        under way is then closed complete and the ``Stopped`` event (every listener hears it) returned."""
        recorder, signals = self.recorder, self.signals
        with signals.installed():
            try:
                recorder.feed(until)
            except KeyboardInterrupt:  # while the device was away
                signals.stopped_by = signals.stopped_by or "SIGINT"
            if signals.stopped_by is None:
                return None
            with signals.during(Phase.CLOSING):
                self.emit(Stopping(signals.stopped_by))
                recorder.stop_decay(DecayEnd.STOPPED)
        stopped = Stopped(signals.stopped_by, recorder.outcomes.count)
        self.emit(stopped)
        return stopped

    def stream_during(self, work: Callable[[], T]) -> T | Stopped:
        """``work()`` (the operator's answer to a question) on a thread of its own while this thread feeds
        the stream; its result once it returns (what it raises is raised here). A signal meanwhile ends
        the stream: the ``Stopped`` is returned and ``work`` is left to end on its own (the answer no
        longer matters; the question is asked again on resume)."""
        answered: Future[T] = Future()

        def answer() -> None:
            try:
                answered.set_result(work())
            except BaseException as exc:  # the operator walked away (EOF, Ctrl-D): raised below
                answered.set_exception(exc)

        threading.Thread(target=answer, name=ASK_THREAD, daemon=True).start()
        stopped = self.stream_until(answered.done)
        return stopped if stopped is not None else answered.result()

    def retarget(self, settings: RecordSettings, run: int) -> None:
        """The next decay's settings and number (``Recorder.retarget``); between decays only."""
        self.recorder.retarget(settings, run)
