"""The workflow's model variants, as settings of ident's one output-error engine, and a view of its fits.

A candidate effect changes the model: a term, Coulomb friction, coupling to a
measured channel, an unmeasured ringing, an observation parameter (per-run
angle offset, angle gain error, angle lag, gyro bias). ``ModelSpec`` says
which; ``fit_spec`` configures ``ident.output_error.OutputErrorFit`` with it
(the equation of motion, the observation model, the exact-sensitivity
Levenberg-Marquardt, the BIC and the standard errors are ident's) and wraps
the result in ``Fit``, the numbers the workflow and its report read. The
workflow's choices: friction smoothed over 0.005 rad/s, measured channels
low-passed at 5 Hz before they force the decay, fixed noise levels as weights
(so every candidate is scored on the same likelihood), white-noise standard
errors, a solver tolerance of 1e-8 (a few dozen refits per diagnosis: the
polish of ident's default 1e-10 costs a factor of about two and moves nothing
the workflow reads) and at most 50 evaluations per refit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ..errors import BadIdentificationInput
from ..ident.output_error import OutputErrorFit
from ..ident.uncertainty import ljung_box
from ..physics.decay import TERMS
from ..records import DecayRun

#: Smoothing rate of the Coulomb term fc*tanh(x'/eps): a dry friction that switches within 0.005 rad/s.
COULOMB_EPS_RAD_S = 0.005
#: Measured channels used as a forcing are low-passed here: ship motions live well below it.
CHANNEL_CUTOFF_HZ = 5.0
#: Solver evaluations per refit. Warm-started, a candidate the data hold converges in 3-15; one they do not
#: (an unmeasured ringing where there is none) can wander for hundreds, and scores badly when cut short.
MAX_EVALUATIONS = 50


@dataclass(frozen=True)
class ModelSpec:
    """A model variant: equation-of-motion terms plus observation parameters."""

    terms: tuple[str, ...] = ("b1", "c1")
    coulomb: bool = False
    coupling: tuple[str, ...] = ()  # measured channels u with a term k_u * u(t)
    offset: bool = False  # per-run angle offset
    gain: bool = False  # angle gain error g: y = (1 + g) x
    lag: bool = False  # angle lag tau relative to the gyro rate
    gyro_bias: bool = False
    ring: bool = False  # an unmeasured motion ringing down at its own frequency forces the decay

    def __post_init__(self) -> None:
        unknown = [t for t in self.terms if t not in TERMS]
        if unknown:
            raise BadIdentificationInput(f"unknown decay term(s) {unknown}; known: {', '.join(TERMS)}")

    @property
    def labels(self) -> list[str]:
        """Everything the model holds, as short names: terms, then fc, k_<channel>, observation flags."""
        flags = [flag for flag in ("offset", "gain", "lag", "gyro_bias", "ring") if getattr(self, flag)]
        return [*self.terms, *(["fc"] if self.coulomb else []), *(f"k_{ch}" for ch in self.coupling), *flags]

    def describe(self) -> str:
        """Short text such as ``b1,c1,b2 + offset + lag``."""
        parts = [",".join(self.terms)]
        if self.coulomb:
            parts.append("coulomb")
        parts += [f"coupling({ch})" for ch in self.coupling]
        for flag in ("offset", "gain", "lag", "gyro_bias"):
            if getattr(self, flag):
                parts.append(flag.replace("_", " "))
        if self.ring:
            parts.append("unmeasured ringing")
        return " + ".join(parts)

    def with_(self, **changes: object) -> ModelSpec:
        return replace(self, **changes)  # type: ignore[arg-type]

    def estimator(self) -> OutputErrorFit:
        """ident's output-error engine set up for this variant, as the workflow fits it."""
        return OutputErrorFit(
            (*self.terms, *(("fc",) if self.coulomb else ())),
            exogenous=self.coupling or None,
            exogenous_cutoff_hz=CHANNEL_CUTOFF_HZ,
            ringing=self.ring,
            friction_eps=COULOMB_EPS_RAD_S,
            fit_offset=self.offset,
            fit_gain=self.gain,
            fit_lag=self.lag,
            fit_gyro_bias=self.gyro_bias,
            cov_type="classic",
            reweight=False,
            tol=1e-8,
            max_nfev=MAX_EVALUATIONS,
            compute_diagnostics=False,
        )


@dataclass
class RunPrediction:
    """The model's view of one run: predicted outputs and residuals (measured - predicted)."""

    name: str
    t: np.ndarray
    angle: np.ndarray
    rate: np.ndarray
    residual_angle: np.ndarray
    residual_rate: np.ndarray | None


@dataclass
class Fit:
    """One converged output-error fit of a ModelSpec: the fitted engine and what the workflow reads of it."""

    spec: ModelSpec
    estimator: OutputErrorFit

    @property
    def coefficients(self) -> dict[str, float]:
        """Every parameter shared by the runs (terms, fc, k_<channel>, observation, ringing)."""
        return self.estimator.shared_params_

    @property
    def std(self) -> dict[str, float]:
        return self.estimator.shared_std_

    @property
    def run_params(self) -> list[dict[str, float]]:
        return self.estimator.run_params_

    @property
    def initial_states(self) -> list[tuple[float, float]]:
        return self.estimator.initial_states_

    @property
    def offsets(self) -> list[float]:
        """Per-run angle offsets, empty when the model has none."""
        return self.estimator.offsets_ if self.spec.offset else []

    @cached_property
    def runs(self) -> list[RunPrediction]:
        fit = self.estimator
        return [
            RunPrediction(run.name, run.t, f["angle"], f["rate"], res["angle"], res["rate"])
            for run, f, res in zip(fit.runs_, fit.fitted_, fit.residuals_, strict=True)
        ]

    @property
    def rss(self) -> float:
        """Sum of squared residuals in units of their noise levels (angle and, when measured, rate)."""
        total = 0.0
        for res, sigma in zip(self.estimator.residuals_, self.estimator.sigmas_, strict=True):
            for output, e in res.items():
                if e is not None:
                    total += float(np.sum((e / sigma[output]) ** 2))
        return total

    @property
    def n(self) -> int:
        return self.estimator.n_obs_

    @property
    def bic(self) -> float:
        return self.estimator.bic_

    @property
    def rms_noise_units(self) -> float:
        """RMS of all outputs in units of their noise level: 1 when only sensor noise is left."""
        return float(np.sqrt(self.rss / self.n))

    @property
    def residual_angle(self) -> np.ndarray:
        return np.concatenate([r.residual_angle for r in self.runs])

    @property
    def rms_angle(self) -> float:
        return float(np.sqrt(np.mean(self.residual_angle**2)))

    @property
    def rms_rate(self) -> float | None:
        parts = [r.residual_rate for r in self.runs if r.residual_rate is not None]
        return float(np.sqrt(np.mean(np.concatenate(parts) ** 2))) if parts else None

    @property
    def nrmse_angle(self) -> float:
        """||y - y_hat|| / ||y - mean(y)|| per run, pooled."""
        return _nrmse([(r.angle + r.residual_angle, r.residual_angle) for r in self.runs])

    @property
    def nrmse_rate(self) -> float | None:
        pairs = [
            (r.rate + r.residual_rate, r.residual_rate) for r in self.runs if r.residual_rate is not None
        ]
        return _nrmse(pairs) if pairs else None

    @property
    def fit_percent(self) -> float:
        return 100.0 * (1.0 - self.nrmse_angle)

    @property
    def ljung_box_p(self) -> float:
        return ljung_box([r.residual_angle for r in self.runs])


def _nrmse(measured_and_residual: Sequence[tuple[np.ndarray, np.ndarray]]) -> float:
    num = sum(float(np.sum(e**2)) for _, e in measured_and_residual)
    den = sum(float(np.sum((y - np.mean(y)) ** 2)) for y, _ in measured_and_residual)
    return float(np.sqrt(num / den))


def fit_spec(
    runs: Sequence[DecayRun],
    spec: ModelSpec,
    start: Fit | None = None,
    guess: dict[str, float] | None = None,
    fixed: dict[str, float] | None = None,
) -> Fit:
    """Fit ``spec`` to all runs jointly by output error (angle, and rate when measured, noise-weighted).

    Warm-started from ``start`` (every parameter it has; new terms from zero),
    else from the equation-error fit with ``guess`` over its coefficients.
    ``fixed`` holds terms at given values (a simulation's own); the rest is fitted.
    """
    estimator = spec.estimator()
    estimator.fit(
        runs, start=guess if start is None else start.estimator, guess=guess, fixed_coefficients=fixed
    )
    return Fit(spec, estimator)


def predict(fit: Fit, runs: Sequence[DecayRun]) -> list[RunPrediction]:
    """The fitted model simulated over other records of the same runs (e.g. the full ones after a cut)."""
    if len(runs) != len(fit.initial_states):
        raise BadIdentificationInput(f"the fit has {len(fit.initial_states)} runs, {len(runs)} were given")
    out = []
    for r, run in enumerate(runs):
        angle, rate = fit.estimator.predict(run, run_index=r)
        residual_rate = None if run.rate is None else run.rate - rate
        out.append(RunPrediction(run.name, run.t, angle, rate, run.angle - angle, residual_rate))
    return out
