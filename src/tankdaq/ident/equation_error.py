"""Equation error: linear least squares of the acceleration on the term regressors.

Instant and convex, so it gives the quick look and the starting values of the
output-error fit; biased towards zero by the noise in the differentiated
signals (reference §4), so it is not the answer.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence

import numpy as np

from ..errors import BadIdentificationInput
from ..physics.models import resolve_model
from ..records import DecayRun
from .base import EstimatorMixin
from .compiled import term_codes, term_matrix
from .derived import linear_stiffness
from .signals import estimate_period, savgol_window, smoothed_derivatives, start_state


def exogenous_input(run: DecayRun, channel: str | None, cutoff_hz: float | None = None) -> np.ndarray:
    """The run's exogenous channel (zeros when the model has none); a missing channel is an input error.

    With ``cutoff_hz`` the channel is taken about its mean (a static part, such as
    gravity in acc_z or the tracker's zero, is an offset, not a forcing) and
    low-passed without phase shift: its sensor noise would otherwise enter as a
    random forcing, a process noise the model cannot have.
    """
    if channel is None:
        return np.zeros_like(run.t)
    if channel not in run.channels:
        known = ", ".join(run.channels) or "none"
        raise BadIdentificationInput(f"{run.name}: no channel {channel!r} to couple (channels: {known})")
    values = np.asarray(run.channels[channel], dtype=float)
    if cutoff_hz is None:
        return values
    centred = values - np.mean(values)
    if centred.size < 30:
        return centred
    from scipy.signal import sosfiltfilt  # about a second to import: only when asked for

    sos = _low_pass(min(cutoff_hz, 0.4 * run.sample_rate), run.sample_rate)
    return sosfiltfilt(sos.copy(), centred)  # a copy: scipy's filter takes a writable array


@functools.lru_cache(maxsize=64)
def _low_pass(cutoff_hz: float, sample_rate_hz: float) -> np.ndarray:
    """The 4th-order Butterworth low-pass of ``exogenous_input`` (second-order sections), designed once
    per cutoff and rate: a diagnosis asks for it at every fit of every run (a tenth of a draw's time)."""
    from scipy.signal import butter

    sos = butter(4, cutoff_hz, fs=sample_rate_hz, output="sos")
    sos.flags.writeable = False  # shared by every caller: never changed
    return sos


def check_runs(runs: Sequence[DecayRun] | DecayRun) -> list[DecayRun]:
    """A non-empty list of runs, each long enough to hold one oscillation."""
    runs = [runs] if isinstance(runs, DecayRun) else list(runs)
    if not runs:
        raise BadIdentificationInput("no runs to fit")
    for run in runs:
        if run.t.size < 20:
            raise BadIdentificationInput(f"{run.name}: {run.t.size} samples are too few to identify a decay")
        if np.ptp(run.angle) <= 0:
            raise BadIdentificationInput(f"{run.name}: the angle does not move")
    return runs


class EquationErrorFit(EstimatorMixin):
    """Least squares of x'' on the model's regressors, pooled over runs.

    Derivatives come from Savitzky-Golay filters over ``window_periods`` of the
    oscillation period, or from the measured gyro rate when present (then only
    one numerical derivative is taken). Each run gets its own intercept, read as
    an angle offset (intercept / linear stiffness).
    """

    def __init__(
        self,
        terms: str | Sequence[str] = "ittc-quadratic-restoring",
        *,
        window_periods: float = 0.15,
        polyorder: int = 3,
        use_rate: bool = True,
        exogenous: str | None = None,
        friction_eps: float = 1e-3,
    ) -> None:
        self.terms = terms
        self.window_periods = window_periods
        self.polyorder = polyorder
        self.use_rate = use_rate
        self.exogenous = exogenous
        self.friction_eps = friction_eps

    def fit(self, runs: Sequence[DecayRun] | DecayRun) -> EquationErrorFit:
        """Fit on one or several runs of one condition; returns self."""
        started = time.perf_counter()
        runs = check_runs(runs)
        self.terms_ = resolve_model(self.terms)
        codes = term_codes(self.terms_)
        blocks, targets, states = [], [], []
        for r, run in enumerate(runs):
            dt = float(np.median(np.diff(run.t)))
            period = estimate_period(run.t, run.angle)
            window = savgol_window(dt, period, self.window_periods, self.polyorder)
            angle_s, rate_s, acc_s = smoothed_derivatives(run.angle, dt, window, self.polyorder)
            if self.use_rate and run.rate is not None:
                rate_s, acc_s, _ = smoothed_derivatives(run.rate, dt, window, self.polyorder)
            keep = np.arange(window // 2, run.t.size - window // 2)
            if run.excluded is not None:  # no row whose smoothing window holds an excluded (clipped) sample
                near = np.convolve(run.excluded.astype(float), np.ones(window), mode="same") > 0
                keep = keep[~near[keep]]
            u = exogenous_input(run, self.exogenous)
            phi = term_matrix(codes, angle_s[keep], rate_s[keep], u[keep], self.friction_eps)
            intercepts = np.zeros((phi.shape[0], len(runs)))
            intercepts[:, r] = 1.0
            blocks.append(np.hstack([-phi, intercepts]))
            targets.append(acc_s[keep])
            angle0, rate0 = start_state(run.t, run.angle, window, self.polyorder)
            if self.use_rate and run.rate is not None:
                rate0 = start_state(run.t, run.rate, window, self.polyorder)[0]
            states.append((angle0, rate0))
        design = np.vstack(blocks)
        target = np.concatenate(targets)
        solution, *_ = np.linalg.lstsq(design, target, rcond=None)
        residual = target - design @ solution
        dof = max(design.shape[0] - design.shape[1], 1)
        sigma2 = float(residual @ residual) / dof
        covariance = sigma2 * np.linalg.pinv(design.T @ design)
        n_theta = len(self.terms_)
        theta = solution[:n_theta]
        self.coefficients_ = dict(zip(self.terms_, theta.tolist(), strict=True))
        std = np.sqrt(np.clip(np.diag(covariance)[:n_theta], 0.0, None))
        self.std_ = dict(zip(self.terms_, std.tolist(), strict=True))
        self.ci95_ = {
            k: (v - 1.96 * s, v + 1.96 * s) for (k, v), s in zip(self.coefficients_.items(), std, strict=True)
        }
        stiffness = linear_stiffness(self.coefficients_)
        scale = stiffness if abs(stiffness) > 1e-12 else 1.0
        self.offsets_ = [float(k / scale) for k in solution[n_theta:]]
        self.initial_states_ = [
            (float(a - off), float(v)) for (a, v), off in zip(states, self.offsets_, strict=True)
        ]
        self.r2_acc_ = float(1.0 - residual @ residual / np.sum((target - target.mean()) ** 2))
        self.elapsed_s_ = time.perf_counter() - started
        return self
