"""Output error: THE estimator. Simulate the decay, compare with what was measured.

All runs of one condition share the coefficients; each run has its own initial
angle and rate (free, so a rough first half-cycle does not bias the fit) and its
own angle offset. Angle and gyro rate are both outputs, each weighted by its
noise level estimated per run. Levenberg-Marquardt on the exact Jacobian from
the sensitivity kernel, started from the equation-error fit.

Optional observation effects for the discrepancy workflow: the angle's gain and
lag relative to the gyro (``angle = gain * x(t - lag) + offset``, second order
in the lag) and a gyro bias (``rate = x' + bias``). They need a measured rate: against
the angle alone a gain or a delay is indistinguishable from the initial state.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..errors import BadIdentificationInput, InputError
from ..physics.models import resolve_model
from ..records import DecayRun
from .derived import natural_period
from .equation_error import EquationError, check_runs, exogenous_input
from .kernels import (
    acceleration_partials,
    simulate,
    simulate_with_sensitivities,
    substeps,
    term_codes,
    term_matrix,
)
from .signals import white_noise_level
from .uncertainty import (
    classic_covariance,
    coefficient_warnings,
    correlation_from_covariance,
    hac_covariance,
    residual_whiteness,
    whiteness_warning,
)

OBSERVATION_PARAMS: tuple[str, ...] = ("gain", "lag_s", "gyro_bias")
#: Below this angle R^2 the fit from the equation-error start is retried from a linear start.
FALLBACK_R2 = 0.9


class _Layout:
    """Where each parameter sits in the vector: coefficients, global observation terms, then per run."""

    def __init__(self, terms: tuple[str, ...], observation: tuple[str, ...], n_runs: int) -> None:
        self.terms = terms
        self.observation = observation
        self.n_runs = n_runs
        self.n_theta = len(terms)
        self.n_global = self.n_theta + len(observation)
        self.size = self.n_global + 3 * n_runs
        self.names = [*terms, *observation] + [
            f"{name}[{r}]" for r in range(n_runs) for name in ("angle0", "rate0", "offset")
        ]

    def obs_index(self, name: str) -> int | None:
        return self.n_theta + self.observation.index(name) if name in self.observation else None

    def run_slice(self, r: int) -> slice:
        start = self.n_global + 3 * r
        return slice(start, start + 3)


class OutputError:
    """Joint output-error fit of a decay model to one or several runs (scikit-learn style).

    Settings: ``terms`` (term list or alias), ``exogenous`` (channel name feeding
    the ``ku`` term), ``friction_eps`` (rad/s, smoothing of the Coulomb sign),
    ``fit_gain`` / ``fit_lag`` / ``fit_gyro_bias`` (observation effects),
    ``use_rate`` (the gyro as a second output), ``cov_type`` ("hac" or
    "classic"), ``hac_periods`` (HAC bandwidth in natural periods), ``reweight``
    (re-estimate the noise levels from the residuals and refit once).

    Fitted: ``coefficients_ std_ ci95_ covariance_ correlation_`` (coefficients),
    ``param_names_ params_ param_covariance_`` (everything), ``offsets_`` (rad)
    and ``initial_states_`` (rad, rad/s) per run, ``fitted_`` and ``residuals_``
    per run ({"angle", "rate"}), ``r2_angle_``, ``nrmse_`` (angle RMS error over
    the angle's peak-to-peak range), ``seed_objective_`` (rad/s), ``bic_``
    (Gaussian, per-run-and-output variances), ``warnings_``,
    ``natural_period_s_``, ``elapsed_s_``; ``gain_ lag_s_ gyro_bias_`` when fitted.
    """

    def __init__(
        self,
        terms: str | Sequence[str] = "ittc-quadratic-restoring",
        *,
        exogenous: str | None = None,
        friction_eps: float = 1e-3,
        fit_gain: bool = False,
        fit_lag: bool = False,
        fit_gyro_bias: bool = False,
        use_rate: bool = True,
        cov_type: str = "hac",
        hac_periods: float = 1.0,
        reweight: bool = True,
        max_nfev: int = 200,
        compute_diagnostics: bool = True,
    ) -> None:
        self.terms = terms
        self.exogenous = exogenous
        self.friction_eps = friction_eps
        self.fit_gain = fit_gain
        self.fit_lag = fit_lag
        self.fit_gyro_bias = fit_gyro_bias
        self.use_rate = use_rate
        self.cov_type = cov_type
        self.hac_periods = hac_periods
        self.reweight = reweight
        self.max_nfev = max_nfev
        self.compute_diagnostics = compute_diagnostics

    def clone(self) -> OutputError:
        """An unfitted copy with the same settings."""
        fresh = copy.copy(self)
        fresh.__dict__ = {k: v for k, v in self.__dict__.items() if not k.endswith("_")}
        return fresh

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        runs: Sequence[DecayRun] | DecayRun,
        start: OutputError | dict[str, float] | None = None,
        fixed_coefficients: dict[str, float] | None = None,
    ) -> OutputError:
        """Fit jointly on ``runs``; returns self.

        ``start``: a fitted OutputError (warm start: all parameters when the runs
        match, else its coefficients) or a coefficient dict; default: the
        equation-error fit. ``fixed_coefficients`` freezes the coefficients and
        fits only the per-run parameters (used to score held-out runs).
        """
        started = time.perf_counter()
        runs = check_runs(runs)
        self._check_settings(runs)
        self.terms_ = resolve_model(self.terms)
        self.runs_ = runs
        observation = tuple(
            name
            for name, wanted in zip(
                OBSERVATION_PARAMS, (self.fit_gain, self.fit_lag, self.fit_gyro_bias), strict=True
            )
            if wanted
        )
        layout = _Layout(self.terms_, observation, len(runs))
        self._layout = layout
        self._codes = term_codes(self.terms_)
        self._inputs = [exogenous_input(run, self.exogenous) for run in runs]
        self._has_rate = [self.use_rate and run.rate is not None for run in runs]
        p0 = self._start_vector(runs, layout, start, fixed_coefficients)
        free = np.ones(layout.size, dtype=bool)
        if fixed_coefficients is not None:
            free[: layout.n_theta] = False
        amplitude = max(float(np.max(np.abs(run.angle - np.median(run.angle)))) for run in runs)
        dt_max = max(float(np.max(np.diff(run.t))) for run in runs)
        self._n_sub = substeps(dt_max, p0[: layout.n_theta], self.terms_, amplitude)
        self._sigmas = [
            self._initial_sigmas(run, has_rate) for run, has_rate in zip(runs, self._has_rate, strict=True)
        ]
        self._predictions: dict[int, tuple[bytes, dict[str, Any]]] = {}

        # with reweighting the first solve only has to get close: the second one polishes
        rough = 1e-6 if self.reweight else 1e-10
        params = self._solve(p0, free, rough)
        if start is None and self._angle_r2(params) < FALLBACK_R2:
            fallback = self._solve(
                self._start_vector(runs, layout, None, fixed_coefficients, True), free, rough
            )
            if self._angle_r2(fallback) > self._angle_r2(params):
                params = fallback
        if self.reweight:
            self._sigmas = self._residual_sigmas(params)
            params = self._solve(params, free, 1e-10)
        self._finish(params, free)
        self._predictions = {}
        self.elapsed_s_ = time.perf_counter() - started
        return self

    def _check_settings(self, runs: list[DecayRun]) -> None:
        if self.cov_type not in ("hac", "classic"):
            raise InputError(f"cov_type {self.cov_type!r}: use 'hac' or 'classic'")
        needs_rate = [
            n
            for n, on in (("gain", self.fit_gain), ("lag", self.fit_lag), ("gyro bias", self.fit_gyro_bias))
            if on
        ]
        if needs_rate and not all(self.use_rate and run.rate is not None for run in runs):
            raise BadIdentificationInput(
                f"fitting the angle's {', '.join(needs_rate)} needs a measured rate in every run "
                f"(against the angle alone it is indistinguishable from the initial state)"
            )

    def _start_vector(
        self,
        runs: list[DecayRun],
        layout: _Layout,
        start: OutputError | dict[str, float] | None,
        fixed: dict[str, float] | None,
        linear_only: bool = False,
    ) -> np.ndarray:
        """Warm start from a fitted estimator of the same shape, else equation error (+ ``start``).

        ``linear_only`` keeps just the linear damping and stiffness of the equation-error
        fit: the fallback when the full start leads the fit astray.
        """
        if (
            isinstance(start, OutputError)
            and start.terms_ == self.terms_
            and start._layout.names == layout.names
        ):
            p0 = start.params_.copy()
        else:
            ee_terms = ("b1", "c1" if "c1" in self.terms_ else "s1") if linear_only else self.terms_
            ee = EquationError(
                ee_terms, use_rate=self.use_rate, exogenous=self.exogenous, friction_eps=self.friction_eps
            ).fit(runs)
            coefficients = dict(ee.coefficients_)
            if isinstance(start, OutputError):
                coefficients.update(start.coefficients_)
            elif start is not None:
                coefficients.update(start)
            p0 = np.zeros(layout.size)
            p0[: layout.n_theta] = [coefficients.get(k, 0.0) for k in self.terms_]
            if (i := layout.obs_index("gain")) is not None:
                p0[i] = 1.0
            for r in range(len(runs)):
                p0[layout.run_slice(r)] = [*ee.initial_states_[r], ee.offsets_[r]]
        if fixed is not None:
            p0[: layout.n_theta] = [fixed.get(k, 0.0) for k in self.terms_]
        return p0

    @staticmethod
    def _initial_sigmas(run: DecayRun, has_rate: bool) -> dict[str, float]:
        """Noise levels from third differences, floored so a clean record does not get infinite weight."""
        floor_angle = 1e-4 * float(np.ptp(run.angle))
        sig = {"angle": max(white_noise_level(run.angle), floor_angle)}
        if has_rate:
            sig["rate"] = max(white_noise_level(run.rate), 1e-4 * float(np.ptp(run.rate)))
        return sig

    def _angle_r2(self, params: np.ndarray) -> float:
        ss_res = ss_tot = 0.0
        for r, run in enumerate(self.runs_):
            pred = self._predict_run(params, r, with_jacobian=False)
            ss_res += float(np.sum((run.angle - pred["angle"]) ** 2))
            ss_tot += float(np.sum((run.angle - run.angle.mean()) ** 2))
        return 1.0 - ss_res / ss_tot

    def _residual_sigmas(self, params: np.ndarray) -> list[dict[str, float]]:
        out = []
        for r, run in enumerate(self.runs_):
            pred = self._predict_run(params, r, with_jacobian=False)
            sig = {"angle": max(_rms(run.angle - pred["angle"]), 1e-12)}
            if self._has_rate[r]:
                sig["rate"] = max(_rms(run.rate - pred["rate"]), 1e-12)
            out.append(sig)
        return out

    def _predict_run(self, params: np.ndarray, r: int, with_jacobian: bool) -> dict[str, Any]:
        """Measured-frame angle and rate of run r, and their Jacobian rows over the full vector.

        The last prediction with Jacobian is kept per run: the solver's final point is asked
        for again by the noise re-estimate, the second solve and the results (about a third of
        a fit's integrations).
        """
        key = params.tobytes()
        cached = self._predictions.get(r)
        if cached is not None and cached[0] == key and (with_jacobian or cached[1]["ok"]):
            return cached[1]
        pred = self._integrate_run(params, r, with_jacobian)
        if with_jacobian:
            self._predictions[r] = (key, pred)
        return pred

    def _integrate_run(self, params: np.ndarray, r: int, with_jacobian: bool) -> dict[str, Any]:
        """``_predict_run`` without the cache."""
        layout = self._layout
        run = self.runs_[r]
        theta = params[: layout.n_theta]
        angle0, rate0, offset = params[layout.run_slice(r)]
        gi, li, bi = (layout.obs_index(n) for n in OBSERVATION_PARAMS)
        gain = params[gi] if gi is not None else 1.0
        lag = params[li] if li is not None else 0.0
        bias = params[bi] if bi is not None else 0.0
        u = self._inputs[r]
        args = (run.t, angle0, rate0, theta, self._codes, u, self.friction_eps, self._n_sub)
        if not with_jacobian:
            x, v = simulate(*args)
            return {"angle": gain * self._lagged(x, v, lag, theta, u) + offset, "rate": v + bias}
        x, v, sx, sv, ok = simulate_with_sensitivities(*args)
        n = run.t.size
        ja = np.zeros((n, layout.size))
        jv = np.zeros((n, layout.size))
        sl = layout.run_slice(r)
        cols = [*range(layout.n_theta), sl.start, sl.start + 1]
        lagged = x
        ja[:, cols] = gain * sx
        if li is not None:
            acc, acc_x, acc_v, phi = acceleration_partials(self._codes, theta, x, v, u, self.friction_eps)
            s_acc = acc_x[:, None] * sx + acc_v[:, None] * sv
            s_acc[:, : layout.n_theta] -= phi
            lagged = x - lag * v + 0.5 * lag**2 * acc
            ja[:, cols] = gain * (sx - lag * sv + 0.5 * lag**2 * s_acc)
            ja[:, li] = gain * (-v + lag * acc)
        jv[:, cols] = sv
        ja[:, sl.start + 2] = 1.0
        if gi is not None:
            ja[:, gi] = lagged
        if bi is not None:
            jv[:, bi] = 1.0
        return {"angle": gain * lagged + offset, "rate": v + bias, "ja": ja, "jv": jv, "ok": ok}

    def _lagged(
        self, x: np.ndarray, v: np.ndarray, lag: float, theta: np.ndarray, u: np.ndarray
    ) -> np.ndarray:
        """x(t - lag) to second order in the lag, x - lag x' + lag^2/2 x'' (error (omega lag)^3 / 6)."""
        if lag == 0.0:
            return x
        acc = acceleration_partials(self._codes, theta, x, v, u, self.friction_eps)[0]
        return x - lag * v + 0.5 * lag**2 * acc

    def _weighted(
        self, params: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, list[tuple[list[np.ndarray], list[np.ndarray]]], bool]:
        """Residuals and Jacobian divided by the noise levels; also per run the (Jacobians, residuals)
        of each output, which the HAC covariance needs instant by instant."""
        res, jac, blocks = [], [], []
        ok_all = True
        for r, run in enumerate(self.runs_):
            pred = self._predict_run(params, r, with_jacobian=True)
            ok_all &= bool(pred["ok"])
            sig = self._sigmas[r]
            run_jac = [-pred["ja"] / sig["angle"]]
            run_res = [(run.angle - pred["angle"]) / sig["angle"]]
            if self._has_rate[r]:
                run_jac.append(-pred["jv"] / sig["rate"])
                run_res.append((run.rate - pred["rate"]) / sig["rate"])
            res += run_res
            jac += run_jac
            blocks.append((run_jac, run_res))
        return np.concatenate(res), np.vstack(jac), blocks, ok_all

    def _solve(self, p0: np.ndarray, free: np.ndarray, tol: float) -> np.ndarray:
        cache: dict[str, Any] = {}

        def evaluate(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            if cache.get("q") is None or not np.array_equal(cache["q"], q):
                p = p0.copy()
                p[free] = q
                res, jac, _, ok = self._weighted(p)
                if not ok:  # diverged: a large, smooth-enough penalty makes LM back off
                    res = np.full_like(res, 1e6)
                cache.update(q=q.copy(), res=res, jac=jac[:, free])
            return cache["res"], cache["jac"]

        result = least_squares(
            lambda q: evaluate(q)[0],
            p0[free],
            jac=lambda q: evaluate(q)[1],
            method="lm",
            x_scale="jac",
            xtol=tol,
            ftol=tol,
            max_nfev=self.max_nfev,
        )
        params = p0.copy()
        params[free] = result.x
        self.nfev_ = int(result.nfev)
        return params

    # ------------------------------------------------------------------ results
    def _finish(self, params: np.ndarray, free: np.ndarray) -> None:
        layout = self._layout
        self.params_ = params
        self.param_names_ = layout.names
        res_w, jac_w, blocks, _ = self._weighted(params)
        self.score_blocks_ = [([j[:, free] for j in js], rs) for js, rs in blocks]
        theta = params[: layout.n_theta]
        self.coefficients_ = dict(zip(self.terms_, theta.tolist(), strict=True))
        self.natural_period_s_ = natural_period(self.coefficients_)
        n_obs = res_w.size
        n_free = int(free.sum())
        if self.cov_type == "hac":
            period_samples = self.natural_period_s_ / float(np.median(np.diff(self.runs_[0].t)))
            bandwidth = (
                max(1, round(self.hac_periods * period_samples)) if math.isfinite(period_samples) else 1
            )
            cov_free = hac_covariance(self.score_blocks_, bandwidth)
        else:
            cov_free = classic_covariance(jac_w[:, free])
        cov_free *= n_obs / max(n_obs - n_free, 1)
        cov = np.zeros((layout.size, layout.size))
        cov[np.ix_(free, free)] = cov_free
        self.param_covariance_ = cov
        self.covariance_ = cov[: layout.n_theta, : layout.n_theta]
        std = np.sqrt(np.clip(np.diag(self.covariance_), 0.0, None))
        self.std_ = dict(zip(self.terms_, std.tolist(), strict=True))
        self.ci95_ = {
            k: (v - 1.96 * s, v + 1.96 * s) for (k, v), s in zip(self.coefficients_.items(), std, strict=True)
        }
        self.correlation_ = correlation_from_covariance(self.covariance_)
        for name in layout.observation:
            setattr(self, f"{name}_", float(params[layout.obs_index(name)]))
        self.offsets_ = [float(params[layout.run_slice(r)][2]) for r in range(layout.n_runs)]
        self.initial_states_ = [
            tuple(map(float, params[layout.run_slice(r)][:2])) for r in range(layout.n_runs)
        ]

        self.fitted_, self.residuals_ = [], []
        ss_res = ss_tot = 0.0
        log_lik_terms = 0.0
        for r, run in enumerate(self.runs_):
            pred = self._predict_run(params, r, with_jacobian=False)
            resid_angle = run.angle - pred["angle"]
            resid_rate = run.rate - pred["rate"] if self._has_rate[r] else None
            self.fitted_.append({"angle": pred["angle"], "rate": pred["rate"]})
            self.residuals_.append({"angle": resid_angle, "rate": resid_rate})
            ss_res += float(resid_angle @ resid_angle)
            ss_tot += float(np.sum((run.angle - run.angle.mean()) ** 2))
            for resid in (resid_angle, resid_rate):
                if resid is not None:
                    log_lik_terms += resid.size * (math.log(2 * math.pi * max(np.mean(resid**2), 1e-300)) + 1)
        self.r2_angle_ = 1.0 - ss_res / ss_tot
        all_angle = np.concatenate([run.angle for run in self.runs_])
        self.nrmse_ = math.sqrt(ss_res / all_angle.size) / float(np.ptp(all_angle))
        self.n_obs_ = n_obs
        self.bic_ = log_lik_terms + n_free * math.log(n_obs)
        self.seed_objective_ = seed_objective(
            self.terms_, theta, self.runs_, self.offsets_, self._inputs, self.friction_eps
        )
        self.warnings_ = []
        if self.compute_diagnostics:
            self.warnings_ = coefficient_warnings(self.terms_, theta, std, self.correlation_)
            for run, resid in zip(self.runs_, self.residuals_, strict=True):
                for output in ("angle", "rate"):
                    if resid[output] is not None:
                        warning = whiteness_warning(run.name, output, *residual_whiteness(resid[output]))
                        if warning:
                            self.warnings_.append(warning)

    def predict(
        self,
        run: DecayRun | np.ndarray,
        run_index: int = 0,
        initial_state: tuple[float, float] | None = None,
        offset: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Measured-frame (angle, rate) of the fitted model at a run's or an array's instants.

        The initial state and offset default to those fitted for ``run_index``
        and apply at the first instant given.
        """
        t = run.t if isinstance(run, DecayRun) else np.asarray(run, dtype=float)
        u = exogenous_input(run, self.exogenous) if isinstance(run, DecayRun) else np.zeros_like(t)
        angle0, rate0 = initial_state if initial_state is not None else self.initial_states_[run_index]
        off = self.offsets_[run_index] if offset is None else offset
        theta = np.array(list(self.coefficients_.values()))
        x, v = simulate(t, angle0, rate0, theta, self._codes, u, self.friction_eps, self._n_sub)
        angle = getattr(self, "gain_", 1.0) * self._lagged(x, v, getattr(self, "lag_s_", 0.0), theta, u)
        return angle + off, v + getattr(self, "gyro_bias_", 0.0)


def seed_objective(
    terms: Sequence[str],
    theta: np.ndarray,
    runs: Sequence[DecayRun],
    offsets: Sequence[float],
    inputs: Sequence[np.ndarray] | None = None,
    friction_eps: float = 1e-3,
) -> float:
    """RMS of the one-step-ahead predicted rate (seed 000 eq. 4.5-4.6), rad/s.

    As in the seeds' software (and ``ident.seed_methods``): one Euler step from
    the measured state at k predicts the rate at k+1; the measured rate is the
    gyro, or the angle differentiated when there is none. The angle is taken
    relative to the fitted offset, the model's equilibrium.
    """
    codes = term_codes(terms)
    errors = []
    for r, (run, offset) in enumerate(zip(runs, offsets, strict=True)):
        x = run.angle - offset
        v = run.rate if run.rate is not None else np.gradient(run.angle, run.t)
        u = np.zeros_like(run.t) if inputs is None else inputs[r]
        acc = -term_matrix(codes, x[:-1], v[:-1], u[:-1], friction_eps) @ theta
        errors.append(v[1:] - (v[:-1] + np.diff(run.t) * acc))
    return _rms(np.concatenate(errors))


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))))
