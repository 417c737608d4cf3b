"""The view's one background thread: jobs run in order, ``put`` never waits, and what falls behind is
dropped and counted, so a slow or dead viewer never holds up acquisition.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

#: Updates (sample blocks, refits) waiting for the view thread beyond this many are dropped:
#: at 50 reads a second the view is then about five seconds behind.
QUEUE_LIMIT = 256
#: With no viewer attached (``--viewer save``) the .rrd is a file for later: updates are dropped only
#: beyond this many waiting (minutes of a decay at 400 Hz; some 40 MB at the very most).
SAVE_QUEUE_LIMIT = 20_000


class ViewFeed:
    """Jobs run in order on one background thread; ``put`` never waits.

    Droppable jobs (sample blocks, refits) beyond ``limit`` waiting are dropped and counted;
    the others (a new run, its end, events) are always kept: a few per decay. A job that
    raises is handed to ``on_error`` and the thread goes on.
    """

    def __init__(self, on_error: Callable[[BaseException], None], limit: int = QUEUE_LIMIT) -> None:
        self.limit = limit
        self.on_error = on_error
        self.dropped = 0
        self.done = 0
        self._jobs: deque[tuple[Callable[[], None], bool]] = deque()
        self._waiting_droppable = 0
        self._busy = False
        self._stopping = False
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._work, name="tankdaq-view", daemon=True)
        self._thread.start()

    def put(self, job: Callable[[], None], droppable: bool) -> bool:
        """Queue ``job``; False when it was dropped (the view is behind)."""
        with self._cond:
            if self._stopping or (droppable and self._waiting_droppable >= self.limit):
                self.dropped += droppable
                return False
            self._jobs.append((job, droppable))
            self._waiting_droppable += droppable
            self._cond.notify_all()
            return True

    def wait_idle(self, stall_s: float, limit_s: float | None = None) -> bool:
        """Wait until every queued job has run; False once no job has finished for ``stall_s`` (a view
        that is stuck), or after ``limit_s`` in all. A view that is only slow (a loaded machine) is
        waited for: what it finishes is what the .rrd keeps."""
        start = time.monotonic()
        with self._cond:
            done, stalled_at = self.done, start + stall_s
            while self._jobs or self._busy:
                now = time.monotonic()
                if self.done != done:
                    done, stalled_at = self.done, now + stall_s
                deadline = stalled_at if limit_s is None else min(stalled_at, start + limit_s)
                if now >= deadline:
                    return False
                self._cond.wait(deadline - now)
            return True

    def stop(self, stall_s: float, limit_s: float | None = None) -> bool:
        """Run what is queued (see ``wait_idle``), then end the thread; False if it did not finish."""
        idle = self.wait_idle(stall_s, limit_s)
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if idle:
            self._thread.join(timeout=1.0)
        return idle

    def _work(self) -> None:
        while True:
            with self._cond:
                while not self._jobs and not self._stopping:
                    self._cond.wait()
                if not self._jobs:
                    return
                job, droppable = self._jobs.popleft()
                self._waiting_droppable -= droppable
                self._busy = True
            try:
                job()
            except Exception as exc:  # whatever rerun raises, acquisition goes on
                self.on_error(exc)
            finally:
                with self._cond:
                    self._busy = False
                    self.done += 1
                    self._cond.notify_all()
