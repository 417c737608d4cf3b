"""An ``OnlineIdentifier`` on a worker thread, so that the acquisition loop only hands samples over.

A refit (10-50 ms, more on a loaded machine) never holds up the reads (the kernels release the
interpreter lock), and a refit that runs past its budget is abandoned (``least_squares.solve_budget``),
with a note.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from ..errors import IdentificationError
from ..ident.least_squares import solve_budget
from .identifier import OnlineIdentifier, OnlineResult

#: How long one live refit may compute (they take 10-50 ms of CPU): past it, it is abandoned at its next
#: evaluation and the next refit starts from the last good one. CPU time on the worker: a loaded PC makes
#: a fit slower, not a runaway (``least_squares.SolveBudget``).
REFIT_BUDGET_S = 5.0
#: The final fit computes for at most its budget (CPU time, as a refit); the caller waits at most this
#: many times the budget on the wall clock, for a worker stuck outside its solver.
FINAL_FIT_WALL_FACTOR = 6.0


#: Samples handed to the worker: time, angle, rate (or None), excluded.
_Samples = tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]


class BackgroundFit:
    """An ``OnlineIdentifier`` run on its own thread: ``submit`` never waits, results come back by ``take``.

    The caller (the read loop) hands over the samples after the release; the worker feeds
    them to the identifier. While a refit runs, newer samples pile up and are given to the
    identifier in one piece when it is done, so at most one refit is ever due, always on the
    latest data (coalesced, never a queue of refits). Results wait in ``take`` for the
    caller's thread, which alone writes them to the file and the view. ``finish`` waits, at
    most ``timeout_s``, for the final fit on everything submitted.

    Every fit on the worker runs under a budget (``refit_budget_s``; the final fit ``finish``'s
    ``timeout_s``): past it, the fit is abandoned at its next evaluation, and ``take_notes`` says
    so. ``close`` (and a ``finish`` past its bound) cancels the fit under way the same way.
    """

    def __init__(self, identifier: OnlineIdentifier, refit_budget_s: float = REFIT_BUDGET_S) -> None:
        self.identifier = identifier
        self.refit_budget_s = refit_budget_s
        self._cancel = threading.Event()
        self._notes: list[str] = []
        self._final_budget_s = refit_budget_s
        self._wake = threading.Condition()
        self._pending: list[_Samples] = []
        self._busy = False  # the worker holds samples it has not finished with
        self._results: list[OnlineResult] = []
        self._finish_requested = False
        self._final_until_t = math.inf
        self._closed = False
        self._final: OnlineResult | None = None
        self._error: BaseException | None = None
        self._done = threading.Event()
        # a daemon thread: a refit stuck past ``finish``'s bound must not keep the process alive
        self._thread = threading.Thread(target=self._work, name="tankdaq-live-fit", daemon=True)
        self._thread.start()

    def submit(
        self,
        t: np.ndarray,
        angle: np.ndarray,
        rate: np.ndarray | None = None,
        excluded: np.ndarray | None = None,
    ) -> None:
        """Hand samples (rad, rad/s; ``excluded``: left out of the fits) to the worker; returns at once."""
        with self._wake:
            self._pending.append((t, angle, rate, np.zeros(t.shape, bool) if excluded is None else excluded))
            self._wake.notify_all()

    def wait_idle(self, timeout_s: float) -> None:
        """Wait (at most ``timeout_s``) until every sample submitted has been through the identifier.

        For a caller that loses nothing by waiting (replay): the same refits every time.
        """
        with self._wake:
            self._wake.wait_for(lambda: not (self._pending or self._busy) or self._done.is_set(), timeout_s)

    def take_notes(self) -> list[str]:
        """What happened on the worker that the record should say (abandoned refits) since the last call."""
        with self._wake:
            notes, self._notes = self._notes, []
        return notes

    def take(self) -> list[OnlineResult]:
        """The refits finished since the last call; a failure of the worker is raised here."""
        with self._wake:
            results, self._results = self._results, []
            error = self._error
        if error is not None and not self._finish_requested:
            raise error
        return results

    def finish(self, timeout_s: float, until_t: float = math.inf) -> tuple[list[OnlineResult], OnlineResult]:
        """Wait (at most ``timeout_s``) for the final fit of the samples up to ``until_t`` (device s); the
        refits not yet taken come with it.

        Raises IdentificationError when the decay cannot be fitted or the fit does not finish
        in time (the worker is then abandoned; the caller closes its file without a final fit).
        """
        with self._wake:
            self._finish_requested = True
            self._final_budget_s = timeout_s
            self._final_until_t = until_t
            self._wake.notify_all()
        if not self._done.wait(timeout_s * FINAL_FIT_WALL_FACTOR):
            self.close()
            raise IdentificationError(
                f"the final fit did not finish within {timeout_s * FINAL_FIT_WALL_FACTOR:g} s; fit the file "
                "afterwards (tankdaq identify)"
            )
        with self._wake:
            results, self._results = self._results, []
        if self._error is not None:
            raise self._error
        assert self._final is not None
        return results, self._final

    def close(self) -> None:
        """Stop without a final fit (an aborted decay); a refit under way stops at its next evaluation."""
        self._cancel.set()
        with self._wake:
            self._closed = True
            self._wake.notify_all()

    def _work(self) -> None:
        try:
            while True:
                with self._wake:
                    while not (self._pending or self._finish_requested or self._closed):
                        self._wake.wait()
                    if self._closed:
                        return
                    pending, self._pending = self._pending, []
                    finishing = self._finish_requested
                    self._busy = True
                if pending:
                    with solve_budget(self.refit_budget_s, self._cancel) as budget:
                        self._update(pending)
                    if budget.abandoned:  # the identifier noted it as a failed refit and goes on
                        self._note_abandoned(budget.seconds)
                with self._wake:
                    self._busy = False
                    self._wake.notify_all()
                if finishing:
                    with solve_budget(self._final_budget_s, self._cancel):
                        self._final = self.identifier.finish(self._final_until_t)
                    return
        except BaseException as exc:  # handed to the caller's thread, where it is raised
            with self._wake:
                self._error = exc
        finally:
            self._done.set()
            with self._wake:
                self._wake.notify_all()

    def _note_abandoned(self, budget_s: float) -> None:
        failures = self.identifier.failures_
        at = failures[-1].split(":", 1)[0] if failures else "a refit"
        with self._wake:
            self._notes.append(
                f"live refit at {at} abandoned past its {budget_s:g} s budget (the model cannot follow "
                "this decay); the next refit starts from the last good one"
            )

    def _update(self, pending: list[_Samples]) -> None:
        rates = [rate for _, _, rate, _ in pending if rate is not None]
        excluded = np.concatenate([excluded for _, _, _, excluded in pending])
        result = self.identifier.update(
            np.concatenate([t for t, _, _, _ in pending]),
            np.concatenate([angle for _, angle, _, _ in pending]),
            np.concatenate(rates) if len(rates) == len(pending) else None,
            **({"excluded": excluded} if excluded.any() else {}),  # said only when there are any
        )
        if result is not None:
            with self._wake:
                self._results.append(result)
