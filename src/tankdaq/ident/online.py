"""Live identification during a decay: refit at every half-cycle, warm-started.

The acquisition loop feeds samples as they arrive after the release. Every time
the angle completes another half-cycle (a zero crossing of the rate), the
output-error fit is redone on everything so far, started from the previous
answer, so each refit costs a few Levenberg-Marquardt steps. Results go to a
callback (the viewer, the recorder's /fit channel) and to ``results_``; a refit
that fails (too little motion yet) is noted in ``failures_`` and skipped. At the
end of the decay the last result is the offline OutputError fit of the same data.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import IdentificationError
from ..records import DecayRun
from .output_error import OutputError
from .signals import band_crossings, white_noise_level


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


class OnlineIdentifier:
    """Feed samples with ``update``; a refit is published at every new half-cycle.

    ``min_half_cycles``: how many complete half-cycles before the first fit (the
    model needs at least a period to see its stiffness). ``horizon_s``: how far
    past the last sample the published curve is predicted. ``check_interval_s``:
    how often (device time) new half-cycles are looked for. Other keyword
    arguments go to the underlying ``OutputError``.
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
        **estimator_settings: object,
    ) -> None:
        self.terms = terms
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
        self._fitted_half_cycles = 0
        self._checked_at = -np.inf
        self.estimator_: OutputError | None = None
        self.results_: list[OnlineResult] = []
        self.failures_: list[str] = []

    def update(self, t: np.ndarray, angle: np.ndarray, rate: np.ndarray | None = None) -> OnlineResult | None:
        """Append samples (rad, rad/s); refit and return the result when a new half-cycle completed.

        Half-cycles are counted at most every ``check_interval_s`` of device time, so feeding
        a few samples at a time at 400 Hz costs almost nothing between refits.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        self._t.append(t)
        self._angle.append(np.atleast_1d(np.asarray(angle, dtype=float)))
        if rate is not None:
            self._rate.append(np.atleast_1d(np.asarray(rate, dtype=float)))
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

    def _run(self) -> DecayRun | None:
        if not self._t:
            return None
        t = np.concatenate(self._t)
        if t.size < 20:
            return None
        rate = np.concatenate(self._rate) if len(self._rate) == len(self._t) else None
        return DecayRun(t=t, angle=np.concatenate(self._angle), rate=rate, axis=self.axis, name="live")

    @staticmethod
    def _half_cycles(run: DecayRun) -> int:
        """Completed half-cycles: crossings of the rate (peaks of the angle) through a 5-sigma noise band.

        The band keeps a settled record's noisy rate from counting as new half-cycles.
        """
        signal = run.rate if run.rate is not None else np.gradient(run.angle, run.t)
        return band_crossings(signal, 5.0 * white_noise_level(signal))

    def _refit(self, run: DecayRun, half_cycles: int) -> OnlineResult:
        started = time.perf_counter()
        estimator = OutputError(self.terms, compute_diagnostics=False, **self.estimator_settings)
        estimator.fit([run], start=self.estimator_)
        self.estimator_ = estimator
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
        )
        self.results_.append(result)
        if self.callback is not None:
            self.callback(result)
        return result
