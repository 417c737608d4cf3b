"""What an output-error fit compares with the measurements: the decay simulated, observed and weighted.

One object per fit holds what stays fixed while the solver moves the parameter vector (the runs, the
parameter layout, the kernel's term codes, the input channels, the noise levels) and answers, for any
vector, each run's measured-frame angle and rate with their exact Jacobian and the noise-weighted
residuals the solver minimises. The estimator (``ident.output_error``) chooses the settings, the start
and the results; this is only the model, so the two can be read apart.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..records import DecayRun
from .compiled import simulate, simulate_with_sensitivities, term_codes
from .forcing import input_forcing
from .observation_lag import LagOperator, end_acceleration_sensitivities, end_accelerations
from .parameter_layout import ParameterLayout

_KU_CODE = term_codes(("ku",))

#: Per run and output: the weighted Jacobians and residuals the HAC covariance needs instant by instant.
ScoreBlocks = list[tuple[list[np.ndarray], list[np.ndarray]]]


class OutputModel:
    """The measured-frame outputs of a parameter vector for every run of one fit.

    ``channels`` are each run's input series, ``has_rate`` whether its gyro rate is an output,
    ``n_sub`` the kernel's sub-steps per sample and ``sigmas`` the noise levels (per run
    ``{"angle", "rate"}``) the residuals are divided by; the fit may re-estimate them between solves.
    """

    def __init__(
        self,
        runs: list[DecayRun],
        layout: ParameterLayout,
        channels: list[list[np.ndarray]],
        has_rate: list[bool],
        friction_eps: float,
        n_sub: int,
        sigmas: list[dict[str, float]],
    ) -> None:
        self.runs = runs
        self.layout = layout
        self.codes = term_codes(layout.dynamics)
        if layout.couplings or layout.ringing:
            self.codes = np.concatenate([self.codes, _KU_CODE])
        self.channels = channels
        self.kept = [run.kept for run in runs]  # residuals of excluded samples (clipped) are left out
        # ...indexed by a slice where none is: a view of each prediction at every evaluation, not a copy
        self._fitted: list[np.ndarray | slice] = [
            kept if not kept.all() else slice(None) for kept in self.kept
        ]
        self.has_rate = has_rate
        self.friction_eps = friction_eps
        self.n_sub = n_sub
        self.sigmas = sigmas
        self._predictions: dict[int, tuple[bytes, dict[str, Any]]] = {}
        self._lag_ops: dict[int, tuple[float, LagOperator]] = {}

    def forget(self) -> None:
        """Drop the solver's caches (a fitted estimator keeps the model to predict, not them)."""
        self._predictions, self._lag_ops = {}, {}

    def kernel_theta(self, params: np.ndarray) -> np.ndarray:
        """The kernel's coefficients: the dynamics terms, then a unit ku when an input is modelled."""
        theta = params[: len(self.layout.dynamics)]
        return np.append(theta, 1.0) if self.codes.size > theta.size else theta.copy()

    def forcing_inputs(self, params: np.ndarray) -> list[np.ndarray]:
        """Each run's input ``u(t)`` at ``params``."""
        layout, channels = self.layout, self.channels
        return [input_forcing(layout, params, r, run.t, channels[r]).u for r, run in enumerate(self.runs)]

    def predictions(self, params: np.ndarray) -> list[dict[str, Any]]:
        """Every run's predicted outputs at ``params`` (no Jacobian)."""
        return [self.predict_run(params, r, with_jacobian=False) for r in range(len(self.runs))]

    def predict_run(self, params: np.ndarray, r: int, with_jacobian: bool) -> dict[str, Any]:
        """Measured-frame angle and rate of run r, and their Jacobian rows over the full vector.

        The last prediction with Jacobian is kept per run: the solver's final point is asked
        for again by the noise re-estimate, the second solve and the results (about a third of
        a fit's integrations).
        """
        key = params.tobytes()
        cached = self._predictions.get(r)
        if cached is not None and cached[0] == key and (with_jacobian or cached[1]["ok"]):
            return cached[1]
        pred = self.integrate(params, r, self.runs[r].t, self.channels[r], with_jacobian)
        if with_jacobian:
            self._predictions[r] = (key, pred)
        return pred

    def integrate(
        self, params: np.ndarray, r: int, t: np.ndarray, channels: list[np.ndarray], with_jacobian: bool
    ) -> dict[str, Any]:
        """Angle and rate of run r's parameters at instants t (and their Jacobian over the full vector)."""
        layout = self.layout
        theta = self.kernel_theta(params)
        forcing = input_forcing(layout, params, r, t, channels)
        angle0, rate0 = (layout.value(params, n, run=r) for n in ("angle0", "rate0"))
        offset = layout.value(params, "angle_offset_rad", run=r)
        gain = 1.0 + layout.value(params, "angle_gain_error")
        lag = layout.value(params, "angle_lag_s")
        bias = layout.value(params, "gyro_bias_rad_s")
        eps, n_sub = self.friction_eps, self.n_sub
        if not with_jacobian:
            x, v = simulate(t, angle0, rate0, theta, self.codes, forcing.u, eps, n_sub)
            if lag != 0.0:
                x = self._lag(r, t, lag).apply(x, v, end_accelerations(self.codes, theta, x, v, forcing, eps))
            return {"angle": gain * x + offset, "rate": v + bias, "ok": True}
        x, v, sx, sv, ok = simulate_with_sensitivities(
            t, angle0, rate0, theta, self.codes, forcing.u, forcing.partials, eps, n_sub
        )
        n_dyn = len(layout.dynamics)
        n_kernel_theta = theta.size
        rs = layout.run_slice(r)
        # kernel columns -> layout columns: dynamics terms, (unit ku: no parameter), x0, v0, input parameters
        kernel_cols = [*range(n_dyn), n_kernel_theta, n_kernel_theta + 1]
        kernel_cols += [n_kernel_theta + 2 + k for k in range(len(forcing.columns))]
        layout_cols = [*range(n_dyn), rs.start, rs.start + 1, *forcing.columns]
        sx_l, sv_l = sx[:, kernel_cols], sv[:, kernel_cols]
        ja = np.zeros((t.size, layout.size))
        jv = np.zeros((t.size, layout.size))
        lagged = x
        if (li := layout.index("angle_lag_s")) is not None:
            op = self._lag(r, t, lag)
            acc_ends, s_acc_ends = end_acceleration_sensitivities(
                self.codes, theta, x, v, forcing, sx, sv, kernel_cols, eps
            )
            lagged = op.apply(x, v, acc_ends)
            ja[:, li] = gain * op.apply_lag_derivative(x, v, acc_ends)
            ja[:, layout_cols] = gain * op.apply(sx_l, sv_l, s_acc_ends)
        else:
            ja[:, layout_cols] = gain * sx_l
        jv[:, layout_cols] = sv_l
        if (oi := layout.run_index(r, "angle_offset_rad")) is not None:
            ja[:, oi] = 1.0
        if (gi := layout.index("angle_gain_error")) is not None:
            ja[:, gi] = lagged
        if (bi := layout.index("gyro_bias_rad_s")) is not None:
            jv[:, bi] = 1.0
        return {"angle": gain * lagged + offset, "rate": v + bias, "ja": ja, "jv": jv, "ok": ok}

    def _lag(self, r: int, t: np.ndarray, lag: float) -> LagOperator:
        """The lag operator on run r's instants, kept while the solver tries other parameters."""
        if t is not self.runs[r].t:
            return LagOperator(t, lag)
        cached = self._lag_ops.get(r)
        if cached is None or cached[0] != lag:
            cached = self._lag_ops[r] = (lag, LagOperator(t, lag))
        return cached[1]

    def weighted(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray, ScoreBlocks, bool]:
        """Residuals and Jacobian divided by the noise levels, the score blocks, and whether all integrated.

        The model is simulated through excluded samples (a clipped stretch): only their residuals
        are left out.
        """
        res, jac, blocks = [], [], []
        ok_all = True
        for r, run in enumerate(self.runs):
            pred = self.predict_run(params, r, with_jacobian=True)
            ok_all &= bool(pred["ok"])
            sig, kept = self.sigmas[r], self._fitted[r]
            run_jac = [-pred["ja"][kept] / sig["angle"]]
            run_res = [(run.angle - pred["angle"])[kept] / sig["angle"]]
            if self.has_rate[r]:
                run_jac.append(-pred["jv"][kept] / sig["rate"])
                run_res.append((run.rate - pred["rate"])[kept] / sig["rate"])
            res += run_res
            jac += run_jac
            blocks.append((run_jac, run_res))
        return np.concatenate(res), np.vstack(jac), blocks, ok_all
