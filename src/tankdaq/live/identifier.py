"""Live identification during a decay: refit at every half-cycle, warm-started.

The acquisition loop feeds samples as they arrive after the release. Every time
the angle completes another half-cycle (a zero crossing of the rate), the
output-error fit is redone on everything so far, started from the previous
answer, so each refit costs a few Levenberg-Marquardt steps. Results go to a
callback (the viewer, the recorder's /fit channel) and to ``results_``; a refit
that fails (too little motion yet) is noted in ``failures_`` and skipped. At the
end of the decay the last result is the offline OutputErrorFit fit of the same data.

``BackgroundFit`` runs an identifier on a worker thread so that the acquisition
loop only hands samples over: a refit (10-50 ms, more on a loaded machine) never
holds up the reads (the kernels release the interpreter lock), and a refit that
runs past its budget is abandoned (``least_squares.solve_budget``), with a note.
``prepare_kernels`` builds or loads the compiled kernels before a
device opens, so no refit pays for them during a decay.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import IdentificationError
from ..ident import compiled
from ..ident.base import EstimatorMixin
from ..ident.least_squares import solve_budget
from ..ident.output_error import OutputErrorFit
from ..ident.plausibility import Implausibility, check_runs
from ..ident.signals import band_crossings, white_noise_level
from ..ident.user_cache import shown
from ..physics.models import MODEL_FAMILY, is_auto, resolve_model
from ..records import DecayRun

#: With ``terms="auto"`` a model of k terms is tried live once the decay has this many half-cycles per term.
HALF_CYCLES_PER_TERM = 2
#: ... and replaces the current one when plausible and its BIC is lower by at least this much.
LIVE_DELTA_BIC = 10.0


@dataclass
class OnlineResult:
    """One published refit: what the viewer draws and the recorder stores."""

    t_end: float
    n_samples: int
    half_cycles: int
    coefficients: dict[str, float]
    std: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    offset: float
    natural_period_s: float
    r2_angle: float
    predicted_t: np.ndarray
    predicted_angle: np.ndarray
    elapsed_s: float
    findings: list[Implausibility] = field(
        default_factory=list
    )  # the fit's implausibilities (``ident.plausibility``)

    @property
    def warnings(self) -> list[str]:
        """The findings' one-line messages."""
        return [finding.message for finding in self.findings]

    def without_curve(self) -> OnlineResult:
        """This result without its predicted curve (empty arrays): what a finished decay keeps. The curve
        is for the view at the time of the fit; kept, it was about 90 kB a decay at 400 Hz (9 MB an hour)."""
        return dataclasses.replace(self, predicted_t=np.empty(0), predicted_angle=np.empty(0))


class OnlineIdentifier(EstimatorMixin):
    """Feed samples with ``update``; a refit is published at every new half-cycle.

    ``min_half_cycles``: how many complete half-cycles before the first fit (the
    model needs at least a period to see its stiffness). ``horizon_s``: how far
    past the last sample the published curve is predicted. ``check_interval_s``:
    how often (device time) new half-cycles are looked for. ``terms="auto"``: the refits start
    with the family's simplest model and move up ``physics.models.MODEL_FAMILY`` as the half-cycles
    allow (``HALF_CYCLES_PER_TERM``) and a plausible larger model wins on BIC, the final fit too
    (``identify``'s held-out choice costs ten fits: on the JIT at load 8 they passed the final
    fit's budget; docs/models.md). ``particulars`` (the hull's GM and
    gyradius) and ``hull`` feed the plausibility checks every result carries. Other keyword
    arguments go to the underlying ``OutputErrorFit``.
    """

    def __init__(
        self,
        terms: str | Sequence[str] = "ittc-quadratic-restoring",
        *,
        callback: Callable[[OnlineResult], None] | None = None,
        min_half_cycles: int = 3,
        horizon_s: float = 0.0,
        axis: str = "roll",
        check_interval_s: float = 0.05,
        particulars: Any = None,
        hull: str = "the hull",
        **estimator_settings: Any,
    ) -> None:
        self.terms = terms
        self.particulars = particulars
        self.hull = hull
        self.callback = callback
        self.min_half_cycles = min_half_cycles
        self.horizon_s = horizon_s
        self.axis = axis
        self.estimator_settings = estimator_settings
        self.check_interval_s = check_interval_s
        self.reset()

    def reset(self) -> None:
        """Forget the current decay (call at each new release)."""
        self._t: list[np.ndarray] = []
        self._angle: list[np.ndarray] = []
        self._rate: list[np.ndarray] = []
        self._excluded: list[np.ndarray] = []
        self._fitted_half_cycles = 0
        self._checked_at = -np.inf
        self.estimator_: OutputErrorFit | None = None
        self.level_ = 0  # with terms="auto": the family's model in use
        self.results_: list[OnlineResult] = []
        self.failures_: list[str] = []

    def update(
        self,
        t: np.ndarray,
        angle: np.ndarray,
        rate: np.ndarray | None = None,
        excluded: np.ndarray | None = None,
    ) -> OnlineResult | None:
        """Append samples (rad, rad/s); refit and return the result when a new half-cycle completed.
        ``excluded``: samples the fits leave out (a sensor clipped; ``DecayRun.excluded``).

        Half-cycles are counted at most every ``check_interval_s`` of device time, so feeding
        a few samples at a time at 400 Hz costs almost nothing between refits.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        self._t.append(t)
        self._angle.append(np.atleast_1d(np.asarray(angle, dtype=float)))
        if rate is not None:
            self._rate.append(np.atleast_1d(np.asarray(rate, dtype=float)))
        self._excluded.append(np.zeros(t.shape, bool) if excluded is None else np.atleast_1d(excluded))
        if t.size == 0 or t[-1] - self._checked_at < self.check_interval_s:
            return None
        self._checked_at = float(t[-1])
        run = self._run()
        if run is None:
            return None
        half_cycles = self._half_cycles(run)
        if half_cycles < self.min_half_cycles or half_cycles <= self._fitted_half_cycles:
            return None
        self._fitted_half_cycles = half_cycles
        try:
            return self._refit(run, half_cycles)
        except IdentificationError as exc:  # a live refit that fails must not stop the acquisition
            self.failures_.append(f"t = {run.t[-1]:.2f} s: {exc}")
            return None

    def finish(self) -> OnlineResult:
        """Final refit on everything received: equals the offline fit of the same data."""
        run = self._run()
        if run is None or (self.estimator_ is None and self._half_cycles(run) < 2):
            raise IdentificationError("the decay ended before a full oscillation: nothing to identify")
        return self._refit(run, self._half_cycles(run))

    @property
    def _auto(self) -> bool:
        return isinstance(self.terms, str) and is_auto(self.terms)

    def _fit(self, terms: Sequence[str], run: DecayRun, start: OutputErrorFit | None) -> OutputErrorFit:
        estimator = OutputErrorFit(terms, compute_diagnostics=False, **self.estimator_settings)
        return estimator.fit([run], start=start)

    def _live_fit(self, run: DecayRun, half_cycles: int) -> OutputErrorFit:
        """The refit of the model in use; with ``terms="auto"``, a plausible larger model of the family
        the half-cycles allow replaces it when its BIC is lower by ``LIVE_DELTA_BIC``."""
        if not self._auto:
            return self._fit(self.terms, run, self.estimator_)
        family = [resolve_model(m) for m in MODEL_FAMILY]
        current = self._fit(family[self.level_], run, self.estimator_)
        for level in range(self.level_ + 1, len(family)):
            if half_cycles < HALF_CYCLES_PER_TERM * len(family[level]):
                break
            try:
                larger = self._fit(family[level], run, current)
            except IdentificationError:
                continue
            findings = check_runs(larger.coefficients_, [run], larger.offsets_, self.particulars)
            plausible = all(finding.about_data for finding in findings)
            if plausible and larger.bic_ < current.bic_ - LIVE_DELTA_BIC:
                current, self.level_ = larger, level
        return current

    def _run(self) -> DecayRun | None:
        if not self._t:
            return None
        t = np.concatenate(self._t)
        if t.size < 20:
            return None
        rate = np.concatenate(self._rate) if len(self._rate) == len(self._t) else None
        excluded = np.concatenate(self._excluded).astype(bool)
        return DecayRun(
            t=t,
            angle=np.concatenate(self._angle),
            rate=rate,
            axis=self.axis,
            name="live",
            excluded=excluded if excluded.any() else None,
        )

    @staticmethod
    def _half_cycles(run: DecayRun) -> int:
        """Completed half-cycles: crossings of the rate (peaks of the angle) through a 5-sigma noise band.

        The band keeps a settled record's noisy rate from counting as new half-cycles.
        """
        signal = run.rate if run.rate is not None else np.gradient(run.angle, run.t)
        return band_crossings(signal, 5.0 * white_noise_level(signal))

    def _refit(self, run: DecayRun, half_cycles: int) -> OnlineResult:
        started = time.perf_counter()
        estimator = self._live_fit(run, half_cycles)
        self.estimator_ = estimator
        findings = check_runs(estimator.coefficients_, [run], estimator.offsets_, self.particulars, self.hull)
        t_pred = run.t
        if self.horizon_s > 0:
            dt = float(np.median(np.diff(run.t)))
            t_pred = np.concatenate([run.t, run.t[-1] + dt * np.arange(1, int(self.horizon_s / dt) + 1)])
        angle_pred, _ = estimator.predict(t_pred)
        result = OnlineResult(
            t_end=float(run.t[-1]),
            n_samples=int(run.t.size),
            half_cycles=half_cycles,
            coefficients=dict(estimator.coefficients_),
            std=dict(estimator.std_),
            ci95=dict(estimator.ci95_),
            offset=estimator.offsets_[0],
            natural_period_s=estimator.natural_period_s_,
            r2_angle=estimator.r2_angle_,
            predicted_t=t_pred,
            predicted_angle=angle_pred,
            elapsed_s=time.perf_counter() - started,
            findings=findings,
        )
        self.results_.append(result)
        if self.callback is not None:
            self.callback(result)
        return result


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

    def finish(self, timeout_s: float) -> tuple[list[OnlineResult], OnlineResult]:
        """Wait (at most ``timeout_s``) for the final fit; the refits not yet taken come with it.

        Raises IdentificationError when the decay cannot be fitted or the fit does not finish
        in time (the worker is then abandoned; the caller closes its file without a final fit).
        """
        with self._wake:
            self._finish_requested = True
            self._final_budget_s = timeout_s
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
                        self._final = self.identifier.finish()
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


def prepare_kernels(terms: str | Sequence[str] = "ittc-quadratic-restoring") -> str | None:
    """Make every kernel a live fit uses ready before a device opens; None, or why not native.

    The native module is built on the first run (``ident.compiled``) and then loads in a
    millisecond. Where it cannot be, numba's JIT compiles (first run) or loads the kernels on a
    made-up decay: the first refit of a decay would otherwise spend 10-40 s compiling (0.6 s
    loading from the cache) wherever it runs.
    """
    reason = compiled.ensure_native()
    if reason is None:
        return None
    t = np.arange(0.0, 12.0, 0.01)
    omega, zeta = 2.0 * np.pi / 2.0, 0.05
    envelope = 0.14 * np.exp(-zeta * omega * t)
    angle = envelope * np.cos(omega * t)
    rate = np.gradient(angle, t)
    identifier = OnlineIdentifier(terms, min_half_cycles=2)
    identifier.update(t[: t.size // 2], angle[: t.size // 2], rate[: t.size // 2])
    identifier.update(t[t.size // 2 :], angle[t.size // 2 :], rate[t.size // 2 :])
    with contextlib.suppress(
        IdentificationError
    ):  # a model this made-up decay does not suit: compiled anyway
        identifier.finish()
    return reason


#: What compiling the kernels took on the 2-core benchmark machine, quiet to loaded (bench_live_fit.py).
FIRST_RUN_S = "10–40"


def first_run_notice() -> str | None:
    """The line a first run says before it builds the kernels (how long, how big, where); None when
    they are ready (or their build failed before: no build is attempted then)."""
    if compiled.ahead_of_time() or compiled.build_failed():
        return None
    return (
        "preparing the identifier (first run after install): building native kernels (once, "
        f"about {FIRST_RUN_S} s, {compiled.NATIVE_SIZE_MB:g} MB) into {shown(compiled.kernel_folder())}"
    )


def prepare_identifier(terms: str | Sequence[str], on_event: Callable[[str], None] | None = None) -> None:
    """``prepare_kernels``, saying so in one line when it means building them (the first run after
    install) and in another when the kernels run on numba's JIT (slower to start) and why."""
    notice = first_run_notice()
    if notice is not None and on_event is not None:
        on_event(notice)
    reason = prepare_kernels(terms)
    if reason is not None and on_event is not None:
        on_event(f"identifier kernels on numba's JIT, slower to start: {reason}")
