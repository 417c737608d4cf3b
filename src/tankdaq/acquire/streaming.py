"""The record daemon held open for a whole guided session: the device opened and configured once (one
handshake), streaming until the session ends.

The session feeds it step by step: ``stream_until`` feeds the stream until the session's condition holds
(the still water measured, the next decay settled), ``stream_during`` feeds it while the operator is
asked a question (the asking on a thread of its own: a long pause piles nothing up), and ``retarget``
sets the next decay's condition (draft, nominal angle, note) between decays. Between steps the reading
thread reads on and its blocks wait in its queue for the next step (a moment: the session's own work):
nothing the device sends is skipped. The pipeline, its sinks, the files and the signal handling are
``record``'s (``acquire.daemon``), the handlers installed for the whole session: a Ctrl-C, SIGTERM or
SIGHUP in a step (a question included) closes the decay under way complete and ends the step with the
typed ``Stopped`` event; one between steps ends the next step at once the same way.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from typing import TypeVar

from ..device.driver import MTiDriver
from ..records import DecayEnd
from .daemon import STOP_NOTES, RecordDaemon, RecordSettings
from .events import Stopped, Stopping
from .pipeline import DecayPipeline
from .read_thread import DeviceReader, Read

T = TypeVar("T")

#: The name of the thread that waits for the operator's answer while the session's thread feeds the stream.
ASK_THREAD = "tankdaq-ask"


class StreamingDaemon(RecordDaemon):
    """``with daemon.streaming():`` the device open; ``stream_until`` and ``retarget`` inside it."""

    _driver: MTiDriver | None = None
    _reader: DeviceReader | None = None

    @contextlib.contextmanager
    def streaming(self) -> Iterator[StreamingDaemon]:
        """Open the device and build the pipeline; at the end (normal, an error, a stop) feed what was
        read, close the decay under way complete, the sinks and the device. The stop signals are the
        daemon's all along: while the device opens a signal raises KeyboardInterrupt (nothing recorded
        yet), between steps it is kept for the next step, which then ends with ``Stopped``."""
        pipeline: DecayPipeline | None = None
        signals = self._signals
        ended = DecayEnd.STOPPED  # a decay under way at the session's end was stopped, or cut by an error
        with signals.installed():
            try:
                self._driver, pipeline = self._start()
                signals.deferred = True
                yield self
            except Exception:
                ended = DecayEnd.ERROR
                raise
            finally:
                signals.deferred = False
                signals.closing = True  # a Ctrl-C now never cuts the file being closed
                try:
                    if pipeline is not None:
                        self._drain(pipeline)
                finally:
                    try:
                        self._shut_down(pipeline, ended)
                    finally:
                        signals.closing = False
                        self._pipeline = None

    @property
    def decay_under_way(self) -> bool:
        """Whether a decay is being recorded (released, not yet settled)."""
        return self._pipeline is not None and self._pipeline.decay is not None

    @property
    def queued_blocks(self) -> int:
        """Blocks read and not yet fed (the reading thread's queue): what a pause in the feeding piles up."""
        return self._reader.queued if self._reader is not None else 0

    def _drain(self, pipeline: DecayPipeline) -> None:
        """The blocks read and not yet fed go to the pipeline (a decay under way keeps them)."""
        reader, self._reader = self._reader, None
        if reader is None:
            return
        try:
            reader.stop()
            for item in reader.items(until=lambda: True):
                if isinstance(item, Read):
                    self._feed(pipeline, item)
        finally:
            reader.close()

    def stream_until(self, until: Callable[[], bool]) -> Stopped | None:
        """Feed the stream until ``until()`` holds (returns None), or until a signal stops it: the decay
        under way is then closed complete and the ``Stopped`` event (every listener hears it) returned."""
        driver, pipeline, signals = self._driver, self._pipeline, self._signals
        assert driver is not None and pipeline is not None, "stream_until runs inside streaming()"
        with signals.installed():
            try:
                while not until() and not self._stop.is_set():
                    reader = self._reader = self._reader or DeviceReader(driver).start()
                    signals.in_loop = True  # a signal now ends the step once the blocks read are fed
                    try:
                        gone = self._stream(pipeline, reader, until)
                    finally:
                        signals.in_loop = False
                    if not until():  # the reader ended (stopped, or the device gone): a new one next
                        self._reader = None
                    if gone is not None:
                        self._device_gone(driver, pipeline, str(gone))
            except KeyboardInterrupt:  # while the device was away
                signals.stopped_by = signals.stopped_by or "SIGINT"
            if signals.stopped_by is None:
                return None
            signals.closing = True
            try:
                self.emit(Stopping(signals.stopped_by))
                pipeline.abort(DecayEnd.STOPPED, STOP_NOTES[DecayEnd.STOPPED])
            finally:
                signals.closing = False
        stopped = Stopped(signals.stopped_by, self.outcomes.count)
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
        """The next decay's settings (a session's condition: draft, nominal angle and its tolerance, the
        note) and number on the device already streaming; between decays only. On port ``sim`` the
        simulated sensor plays that decay next (``SimulatedMTi.play``): the operator's tilt and release."""
        driver, pipeline, recording = self._driver, self._pipeline, self._recording
        assert driver is not None and pipeline is not None and recording is not None, "inside streaming()"
        assert pipeline.decay is None, "the condition changes between decays"
        self.hull = settings.check()
        self.settings = settings
        metadata, config = self._file_header(driver)
        recording.run_metadata, recording.run_config = metadata, dict(config)
        recording.draft, recording.nominal_angle_deg = settings.draft, settings.angle_deg
        pipeline.next_run = run
        pipeline.settings = dataclasses.replace(
            pipeline.settings, angle_deg=settings.angle_deg, angle_tolerance_deg=settings.angle_tolerance_deg
        )
        if self.simulator is not None and self.replayed is None:
            self.simulator.play(self.simulation_scenario())
