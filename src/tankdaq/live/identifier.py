"""Live identification during a decay: refit at every half-cycle, warm-started.

The acquisition loop feeds samples as they arrive after the release. Every time
the angle completes another half-cycle (a zero crossing of the rate), the
output-error fit is redone on everything so far, started from the previous
answer, so each refit costs a few Levenberg-Marquardt steps. Results go to a
callback (the viewer, the recorder's /fit channel) and to ``results_``; a refit
that fails (too little motion yet) is noted in ``failures_`` and skipped. At the
end of the decay the last result is the offline ``OutputErrorFit`` of the same data,
started cold: the file's fit depends on its samples only, not on when the refits ran.

It runs on a worker thread (``live.worker``) on kernels made ready before a device opens
(``live.preparation``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import IdentificationError
from ..ident.base import EstimatorMixin
from ..ident.output_error import OutputErrorFit
from ..ident.plausibility import Implausibility, check_runs
from ..ident.signals import band_crossings, white_noise_level
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
        is for the view at the time of the fit; kept, it would be some 90 kB a decay at 400 Hz."""
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

    def finish(self, until_t: float = math.inf) -> OnlineResult:
        """Final fit on the samples received up to ``until_t`` (device s; the instant the decay's end was
        decided), from the data alone: started as the offline fit starts, the model (``terms="auto"``)
        chosen again from the family's simplest. Which refits ran, and how far past the end the last read
        reached, depend on the machine's timing; the file's fit must not: the same samples give the same
        fit, bit for bit."""
        run = self._run(until_t)
        half_cycles = 0 if run is None else self._half_cycles(run)
        if run is None or (self.estimator_ is None and half_cycles < 2):
            raise IdentificationError("the decay ended before a full oscillation: nothing to identify")
        self.estimator_, self.level_ = None, 0
        return self._refit(run, half_cycles)

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

    def _run(self, until_t: float = math.inf) -> DecayRun | None:
        """Everything received (up to ``until_t``, device s) as one run; None before 20 samples."""
        if not self._t:
            return None
        t = np.concatenate(self._t)
        kept = int(np.searchsorted(t, until_t, side="right"))
        if kept < 20:
            return None
        rate = np.concatenate(self._rate)[:kept] if len(self._rate) == len(self._t) else None
        excluded = np.concatenate(self._excluded).astype(bool)[:kept]
        return DecayRun(
            t=t[:kept],
            angle=np.concatenate(self._angle)[:kept],
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
