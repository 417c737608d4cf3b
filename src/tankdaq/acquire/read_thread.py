"""The thread that takes the device's reads and does nothing else.

Release confirmation, pre-trigger writing, fit hand-off and file work take a good part of a second
once per decay: run on the reading thread, they would leave the bytes that long in the port's
buffers. A thread of its own is not enough either, since it shares the interpreter with the
pipeline, the live fit and the view. So where the port is a path the reads
are made by a process of their own (``device.read_process``: every ``READ_INTERVAL_S``, stamped
there), and ``DeviceReader``'s thread (``tankdaq-read``) only decodes them into blocks; for a
pyserial URL it reads itself. Each block is queued with the link counters as of that read; the
record daemon's thread takes the blocks and runs the pipeline. The queue is bounded generously and
never drops: a reader that gets that far ahead waits for the pipeline. Stopping, the reader ends
after its current read and every block it read still comes out of ``items`` (nothing read is lost).
"""

from __future__ import annotations

import contextlib
import dataclasses
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ..device.driver import MTiDriver, StreamBlock, StreamCounters

#: Reads are spaced at least this far apart: blocks of a few samples instead of one, so the
#: per-block work (decode, detect, write, view) is shared; 20 ms is invisible in a live view.
READ_INTERVAL_S = 0.02

#: Blocks the queue holds before the reader waits (never drops): a minute of reads at 20 ms.
QUEUE_BLOCKS = 3000

#: The name of the thread that takes the reads (a test checks that no release, fit or write runs on it).
THREAD_NAME = "tankdaq-read"


@dataclass(frozen=True)
class Read:
    """One read: the block, and the link counters just after it (what the pipeline has seen)."""

    block: StreamBlock
    counters: StreamCounters


@dataclass(frozen=True)
class Ended:
    """The reader ended: ``error`` is what the read raised (``DeviceGone``, a bug), None when stopped."""

    error: BaseException | None


class DeviceReader:
    """Reads ``driver`` on the ``tankdaq-read`` thread from ``start()`` until ``stop()`` or an error."""

    def __init__(self, driver: MTiDriver, interval_s: float = READ_INTERVAL_S) -> None:
        self.driver = driver
        self.interval_s = interval_s
        self._queue: queue.Queue[Read | Ended] = queue.Queue(maxsize=QUEUE_BLOCKS)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name=THREAD_NAME, daemon=True)

    def start(self) -> DeviceReader:
        self._thread.start()
        return self

    @property
    def queued(self) -> int:
        """Blocks read and not yet taken by ``items``."""
        return self._queue.qsize()

    def stop(self) -> None:
        """End after the current read; what was read still comes out of ``items``."""
        self._stop.set()

    def _read(self) -> None:
        try:
            for block in self._blocks():
                counters = self.driver.counters
                snapshot = dataclasses.replace(counters, device_errors=list(counters.device_errors))
                self._queue.put(Read(block, snapshot))
        except BaseException as exc:  # the daemon's thread raises it (DeviceGone: it reconnects)
            self._queue.put(Ended(exc))
        else:
            self._queue.put(Ended(None))

    def _blocks(self) -> Iterator[StreamBlock]:
        """The driver's blocks until stopped: read by a process of their own where the port is a path
        (``device.read_process``), else by this thread."""
        if self.driver.reads_in_process_possible:
            yield from self.driver.reads_in_process(self._stop, self.interval_s)
            return
        next_read = 0.0
        while not self._stop.is_set():
            wait = next_read - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                break
            next_read = time.monotonic() + self.interval_s
            yield self.driver.read_block()

    def items(self, until: Callable[[], bool], poll_s: float = 0.05) -> Iterator[Read | Ended]:
        """The reads in order, then the ``Ended`` that closes them; once ``until()`` is true the reader is
        stopped and what it read before comes out first."""
        while True:
            if until():
                self.stop()
            try:
                item = self._queue.get(timeout=poll_s)
            except queue.Empty:
                continue
            yield item
            if isinstance(item, Ended):
                return

    def close(self) -> None:
        """Stop and wait for the thread (one read at most), discarding what is still queued."""
        self.stop()
        while self._thread.is_alive():
            with contextlib.suppress(queue.Empty):
                self._queue.get(timeout=0.05)  # a reader waiting on a full queue is let go
        self._thread.join()
