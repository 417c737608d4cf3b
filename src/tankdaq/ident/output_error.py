"""Output error: THE estimator. Simulate the decay, compare with what was measured.

All runs of one condition share the coefficients; each run has its own initial
angle and rate (free, so a rough first half-cycle does not bias the fit) and,
by default, its own angle offset. Angle and gyro rate are both outputs, each
weighted by its noise level estimated per run. Levenberg-Marquardt on the
exact Jacobian from the sensitivity kernel, started from the equation-error fit
or warm-started from another fit.

One parameter layout and one observation model serve every use, the
discrepancy workflow included (it only chooses the settings):

- equation of motion: the terms (b1..s3, Coulomb friction ``fc``) and an input
  ``u(t)`` entering as ``ku*u``: measured channels, each with its coupling
  coefficient (``ku`` for the one channel of the ``ku`` term, else
  ``k_<channel>``), plus optionally an unmeasured motion ringing down at its own
  frequency, ``exp(-l t) (p cos wt + q sin wt)`` (w, l shared; p, q per run);
- observation: ``angle = (1 + g) x(t - lag) + offset`` (x(t - lag) by cubic
  Hermite interpolation on the simulated angle and rate, second-order Taylor
  beyond the ends), ``rate = x' + gyro_bias``. Gain error, lag and gyro bias
  need a measured rate: against the angle alone they are indistinguishable
  from the initial state.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from ..errors import BadIdentificationInput, InputError
from ..physics.models import resolve_model
from ..records import DecayRun
from .base import EstimatorMixin
from .compiled import substeps
from .derived import natural_period
from .equation_error import EquationErrorFit, check_runs, exogenous_input
from .fit_statistics import (
    angle_r2,
    initial_noise_levels,
    residual_noise_levels,
    summarize_residuals,
    whiteness_warnings,
)
from .least_squares import levenberg_marquardt
from .one_step import one_step_rms
from .output_model import OutputModel
from .parameter_layout import OBSERVATION_PARAMS, ParameterLayout
from .uncertainty import (
    bic,
    classic_covariance,
    coefficient_warnings,
    correlation_from_covariance,
    hac_covariance,
)

#: Below this angle R^2 the fit from the equation-error start is retried from a linear start.
FALLBACK_R2 = 0.9


class OutputErrorFit(EstimatorMixin):
    """Joint output-error fit of a decay model to one or several runs (scikit-learn style).

    Settings: ``terms`` (term list or alias; ``ku`` couples the one ``exogenous``
    channel), ``exogenous`` (channel name or names forcing the decay; without a
    ``ku`` term each gets a coefficient ``k_<channel>``), ``exogenous_cutoff_hz``
    (None: channels as measured; else about their mean and low-passed there),
    ``ringing`` (an unmeasured motion ringing down at its own frequency forces
    the decay), ``friction_eps`` (rad/s, smoothing of the Coulomb sign),
    ``fit_offset`` (per-run angle offset), ``fit_gain`` / ``fit_lag`` /
    ``fit_gyro_bias`` (observation effects), ``use_rate`` (the gyro as a
    second output), ``cov_type`` ("hac" or "classic"), ``hac_periods`` (HAC
    bandwidth in natural periods), ``reweight`` (re-estimate the noise levels
    from the residuals and refit once; without, the model-free noise levels
    stay the weights and the BIC's noise model), ``tol`` (the final solve's relative
    tolerance on the parameters and the cost), ``max_nfev``,
    ``compute_diagnostics`` (warnings about terms and residuals).

    Fitted: ``coefficients_ std_ ci95_ covariance_ correlation_`` (the terms),
    ``param_names_ params_ param_covariance_`` (everything), ``shared_params_``
    and ``shared_std_`` (every parameter shared by the runs, by name),
    ``run_params_`` (each run's own, by name), ``offsets_`` (rad) and
    ``initial_states_`` (rad, rad/s) per run, ``fitted_`` and ``residuals_`` per
    run ({"angle", "rate"}), ``sigmas_`` (the noise levels weighting them),
    ``r2_angle_``, ``nrmse_`` (angle RMS error over the angle's peak-to-peak
    range), ``seed_objective_`` (rad/s), ``bic_``, ``n_obs_``, ``warnings_``,
    ``natural_period_s_``, ``elapsed_s_``; ``angle_gain_error_ angle_lag_s_
    gyro_bias_rad_s_`` when fitted.
    """

    def __init__(
        self,
        terms: str | Sequence[str] = "ittc-quadratic-restoring",
        *,
        exogenous: str | Sequence[str] | None = None,
        exogenous_cutoff_hz: float | None = None,
        ringing: bool = False,
        friction_eps: float = 1e-3,
        fit_offset: bool = True,
        fit_gain: bool = False,
        fit_lag: bool = False,
        fit_gyro_bias: bool = False,
        use_rate: bool = True,
        cov_type: str = "hac",
        hac_periods: float = 1.0,
        reweight: bool = True,
        tol: float = 1e-10,
        max_nfev: int = 200,
        compute_diagnostics: bool = True,
    ) -> None:
        self.terms = terms
        self.exogenous = exogenous
        self.exogenous_cutoff_hz = exogenous_cutoff_hz
        self.ringing = ringing
        self.friction_eps = friction_eps
        self.fit_offset = fit_offset
        self.fit_gain = fit_gain
        self.fit_lag = fit_lag
        self.fit_gyro_bias = fit_gyro_bias
        self.use_rate = use_rate
        self.cov_type = cov_type
        self.hac_periods = hac_periods
        self.reweight = reweight
        self.tol = tol
        self.max_nfev = max_nfev
        self.compute_diagnostics = compute_diagnostics

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        runs: Sequence[DecayRun] | DecayRun,
        start: OutputErrorFit | dict[str, float] | None = None,
        fixed_coefficients: dict[str, float] | None = None,
        guess: dict[str, float] | None = None,
    ) -> OutputErrorFit:
        """Fit jointly on ``runs``; returns self.

        ``start``: a fitted OutputErrorFit (warm start: every parameter it has, by
        name; each run's own when the runs match, else the equation-error ones)
        or a coefficient dict over the equation-error fit; default: the
        equation-error fit. ``guess`` gives parameters nothing else starts (the
        ringing's frequency, say). ``fixed_coefficients`` freezes the terms it
        names at its values and fits the rest: every term given, only the per-run
        parameters (held-out runs are scored so); some, the others on top of them
        (a simulation's own terms kept, only the added ones fitted).
        """
        started = time.perf_counter()
        runs = check_runs(runs)
        self._check_settings(runs)
        self.terms_ = resolve_model(self.terms)
        self.runs_ = runs
        layout = self._layout = self._make_layout(len(runs))
        p0 = self._start_vector(runs, start, fixed_coefficients, guess or {})
        free = np.ones(layout.size, dtype=bool)
        if fixed_coefficients is not None:
            free[[layout.at(k) for k in self.terms_ if k in fixed_coefficients]] = False
        amplitude = max(float(np.max(np.abs(run.angle - np.median(run.angle)))) for run in runs)
        dt_max = max(float(np.max(np.diff(run.t))) for run in runs)
        self._n_sub = substeps(dt_max, p0[: len(layout.dynamics)], layout.dynamics, amplitude)
        has_rate = [self.use_rate and run.rate is not None for run in runs]
        sigmas = [initial_noise_levels(run, rated) for run, rated in zip(runs, has_rate, strict=True)]
        channels = [self._channel_series(run) for run in runs]
        model = OutputModel(runs, layout, channels, has_rate, self.friction_eps, self._n_sub, sigmas)
        self._model = model

        # with reweighting the first solve only has to get close: the second one polishes
        rough = max(1e-6, self.tol) if self.reweight else self.tol
        params = self._solve(p0, free, rough)
        if start is None and angle_r2(runs, model.predictions(params), model.kept) < FALLBACK_R2:
            linear = self._start_vector(runs, None, fixed_coefficients, guess or {}, linear_only=True)
            fallback = self._solve(linear, free, rough)
            if angle_r2(runs, model.predictions(fallback), model.kept) > angle_r2(
                runs, model.predictions(params), model.kept
            ):
                params = fallback
        if self.reweight:
            model.sigmas = residual_noise_levels(runs, model.predictions(params), model.kept, has_rate)
            params = self._solve(params, free, self.tol)
        self._finish(params, free)
        model.forget()
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

    @property
    def _channel_names(self) -> tuple[str, ...]:
        if self.exogenous is None:
            return ()
        return (self.exogenous,) if isinstance(self.exogenous, str) else tuple(self.exogenous)

    def _make_layout(self, n_runs: int) -> ParameterLayout:
        observation = tuple(name for name, setting in OBSERVATION_PARAMS.items() if getattr(self, setting))
        return ParameterLayout.for_model(
            self.terms_, self._channel_names, self.ringing, observation, self.fit_offset, n_runs
        )

    def _channel_series(self, run: DecayRun) -> list[np.ndarray]:
        return [exogenous_input(run, ch, self.exogenous_cutoff_hz) for ch in self._channel_names]

    def _start_vector(
        self,
        runs: list[DecayRun],
        start: OutputErrorFit | dict[str, float] | None,
        fixed: dict[str, float] | None,
        guess: dict[str, float],
        linear_only: bool = False,
    ) -> np.ndarray:
        """Warm start from a fitted estimator by name, else equation error (+ ``start``), then ``guess``.

        ``linear_only`` keeps just the linear damping and stiffness of the equation-error
        fit: the fallback when the full start leads the fit astray.
        """
        layout = self._layout
        known: dict[str, float] = {}
        per_run: list[dict[str, float]] = []
        if isinstance(start, OutputErrorFit):
            start.check_fitted()
            if start._layout.names == layout.names:
                return self._fix(start.params_.copy(), fixed)
            # a swapped spring (c1*x <-> s1*sin x) starts from the stiffness it replaces
            swapped = {"s1": start.shared_params_.get("c1"), "c1": start.shared_params_.get("s1")}
            known = {k: v for k, v in swapped.items() if v is not None} | start.shared_params_
            if start._layout.n_runs == len(runs):
                per_run = [dict(p) for p in start.run_params_]
        if not per_run:
            ee = self._equation_error_start(runs, linear_only)
            known = ee.coefficients_ | known
            if isinstance(start, dict):
                known |= start
            per_run = [
                {"angle0": a0, "rate0": v0, "angle_offset_rad": off}
                for (a0, v0), off in zip(ee.initial_states_, ee.offsets_, strict=True)
            ]
        return self._fix(layout.vector(known, per_run, guess), fixed)

    def _fix(self, p0: np.ndarray, fixed: dict[str, float] | None) -> np.ndarray:
        if fixed is not None:
            for k in self.terms_:
                if k in fixed:
                    p0[self._layout.at(k)] = fixed[k]
        return p0

    def _equation_error_start(self, runs: list[DecayRun], linear_only: bool) -> EquationErrorFit:
        """Equation error on the dynamics (and the ku channel): the usual start."""
        if linear_only:
            terms: tuple[str, ...] = ("b1", "c1" if "c1" in self.terms_ else "s1")
        else:
            terms = self._layout.dynamics + (("ku",) if "ku" in self.terms_ else ())
        exogenous = self._channel_names[0] if "ku" in terms else None
        return EquationErrorFit(
            terms, use_rate=self.use_rate, exogenous=exogenous, friction_eps=self.friction_eps
        ).fit(runs)

    def _solve(self, p0: np.ndarray, free: np.ndarray, tol: float) -> np.ndarray:
        def evaluate(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            p = p0.copy()
            p[free] = q
            res, jac, _, ok = self._model.weighted(p)
            if not ok:  # diverged: a large penalty makes LM refuse the step and back off
                res = np.full_like(res, 1e6)
            return res, jac[:, free]

        result = levenberg_marquardt(evaluate, p0[free], xtol=tol, ftol=tol, max_nfev=self.max_nfev)
        params = p0.copy()
        params[free] = result.x
        self.nfev_ = result.nfev
        return params

    # ------------------------------------------------------------------ results
    def _finish(self, params: np.ndarray, free: np.ndarray) -> None:
        layout = self._layout
        if not np.all(np.isfinite(params)):
            raise BadIdentificationInput("the fit diverged: no finite parameters; try a simpler model")
        self.params_ = params
        self.param_names_ = layout.names
        model = self._model
        self.sigmas_ = model.sigmas
        res_w, jac_w, blocks, _ = model.weighted(params)
        self.score_blocks_ = [([j[:, free] for j in js], rs) for js, rs in blocks]
        term_index = [layout.at(k) for k in self.terms_]
        theta = params[term_index]
        self.coefficients_ = dict(zip(self.terms_, theta.tolist(), strict=True))
        self.natural_period_s_ = natural_period(self.coefficients_)
        n_obs = res_w.size
        n_free = int(free.sum())
        cov = np.zeros((layout.size, layout.size))
        cov[np.ix_(free, free)] = self._free_covariance(res_w, jac_w, free)
        self.param_covariance_ = cov
        self.covariance_ = cov[np.ix_(term_index, term_index)]
        std = np.sqrt(np.clip(np.diag(self.covariance_), 0.0, None))
        self.std_ = dict(zip(self.terms_, std.tolist(), strict=True))
        self.ci95_ = {
            k: (v - 1.96 * s, v + 1.96 * s) for (k, v), s in zip(self.coefficients_.items(), std, strict=True)
        }
        self.correlation_ = correlation_from_covariance(self.covariance_)
        all_std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        self.shared_params_ = {name: float(params[i]) for i, name in enumerate(layout.shared)}
        self.shared_std_ = {name: float(all_std[i]) for i, name in enumerate(layout.shared)}
        self.run_params_ = [
            dict(zip(layout.per_run, params[layout.run_slice(r)].tolist(), strict=True))
            for r in range(layout.n_runs)
        ]
        for name in OBSERVATION_PARAMS:
            if name in self.shared_params_:
                setattr(self, f"{name}_", self.shared_params_[name])
        self.offsets_ = [p.get("angle_offset_rad", 0.0) for p in self.run_params_]
        self.initial_states_ = [(p["angle0"], p["rate0"]) for p in self.run_params_]

        predictions = model.predictions(params)
        summary = summarize_residuals(self.runs_, predictions, model.kept, model.has_rate, model.sigmas)
        self.fitted_, self.residuals_ = summary.fitted, summary.residuals
        self.r2_angle_, self.nrmse_ = summary.r2_angle, summary.nrmse
        self.n_obs_ = n_obs
        self.bic_ = bic(summary.blocks, n_free, None if self.reweight else summary.block_sigmas)
        self.seed_objective_ = one_step_rms(
            model.codes,
            model.kernel_theta(params),
            self.runs_,
            self.offsets_,
            model.forcing_inputs(params),
            self.friction_eps,
        )
        self.warnings_ = []
        if self.compute_diagnostics:
            self.warnings_ = coefficient_warnings(self.terms_, theta, std, self.correlation_)
            self.warnings_ += whiteness_warnings(self.runs_, self.residuals_, model.kept)

    def _free_covariance(self, res_w: np.ndarray, jac_w: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Covariance of the free parameters: HAC over about ``hac_periods`` natural periods (the residuals
        of a decay are coloured), or classic."""
        n_obs, n_free = res_w.size, int(free.sum())
        if self.cov_type == "hac":
            period_samples = self.natural_period_s_ / float(np.median(np.diff(self.runs_[0].t)))
            bandwidth = (
                max(1, round(self.hac_periods * period_samples)) if math.isfinite(period_samples) else 1
            )
            return hac_covariance(self.score_blocks_, bandwidth) * n_obs / max(n_obs - n_free, 1)
        return classic_covariance(jac_w[:, free], res_w, n_free)

    def predict(
        self,
        run: DecayRun | np.ndarray,
        run_index: int = 0,
        initial_state: tuple[float, float] | None = None,
        offset: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Measured-frame (angle, rate) of the fitted model at a run's or an array's instants.

        The initial state, offset and ringing amplitudes default to those fitted
        for ``run_index`` and apply at the first instant given. A model forced by
        measured channels needs the run that holds them.
        """
        self.check_fitted()
        if isinstance(run, DecayRun):
            t, channels = run.t, self._channel_series(run)
        else:
            if self._layout.couplings:
                raise BadIdentificationInput("the model is forced by measured channels: predict on a run")
            t, channels = np.asarray(run, dtype=float), []
        params = self.params_.copy()
        if initial_state is not None:
            params[[self._layout.run_at(run_index, n) for n in ("angle0", "rate0")]] = initial_state
        if offset is not None and (i := self._layout.run_index(run_index, "angle_offset_rad")) is not None:
            params[i] = offset
        pred = self._model.integrate(params, run_index, t, channels, with_jacobian=False)
        if offset is not None and self._layout.run_index(run_index, "angle_offset_rad") is None:
            pred["angle"] = pred["angle"] + offset
        return pred["angle"], pred["rate"]
