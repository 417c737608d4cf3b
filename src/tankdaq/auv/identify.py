"""Separate identification of the diving-plane derivatives: one linear regression per equation.

Each of seed 003's equations 1(a)-(c) is linear in its viscous derivatives once the added-mass terms
(taken as known, as the seed does for the inertia coefficients), the rigid-body terms, the thrust and
the hydrostatics are moved to the left. Divided by rho/2 L^2 U0^2 (X, Z) or rho/2 L^3 U0^2 (M), with U0
the nominal speed, the coefficients are the prime derivatives and the regressors non-dimensional
(u' = u/U0, w' = w/U0, q' = qL/U0):

    surge   y_X = X'wq w'q' + X'u|u| u'|u'| + X'dsds u'^2 ds^2 + b_X
    heave   y_Z = Z'uq u'q' + Z'uu u'^2 + Z'uw u'w' + Z'w|w| w'|w'| + Z'ds u'^2 ds + b_Z
    pitch   y_M = M'q|q| q'|q'| + M'uq u'q' + M'uu u'^2 + M'uw u'w' + M'w|w| w'|w'| + M'ds u'^2 ds + b_M

The intercept b (the LS-SVM bias) is a constant force the model does not have; it should come out near 0.

Accelerations: the whole equation is filtered with one smooth kernel h(s) = (1 - s^2)^4 of full width
``window_s`` (the weak form). The accelerations become h' * state (summation by parts, exact up to
quadrature error because h and h' vanish at the window edges) and every regressor becomes h * regressor,
computed from the raw states. So the filtered equation holds exactly on noise-free data whatever the
window, plane reversals included; on noisy data the window averages the noise away (a wider window
smooths more but keeps fewer independent samples).

Estimators: ``LSSVMRegressor`` (linear kernel, solved in its primal form, i.e. ridge regression with an
unpenalised intercept, which equals the dual system [[0, 1^T], [1, K + I/gamma]] [b; alpha] = [0; y];
gamma chosen by blocked cross-validation on contiguous parts of the manoeuvre) and
``LeastSquaresRegressor`` (gamma -> infinity). Standard errors: OLS covariance s^2 (X^T X)^-1, the ridge
sandwich s^2 A^-1 X^T X A^-1 for LS-SVM. Residuals of filtered data are correlated, so both are
optimistic.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import BadIdentificationInput, InputError
from ..ident.base import EstimatorMixin
from .model import STATE_COLUMNS, StateRecord
from .vehicle import TERM_BY_NAME, VISCOUS_TERMS, Vehicle

EQUATIONS: tuple[str, ...] = ("X", "Z", "M")
#: The rho/2 L^n power each equation is divided by.
_EQUATION_POWER: dict[str, int] = {"X": 2, "Z": 2, "M": 3}

#: What each viscous derivative multiplies, from the non-dimensional u', w', q' and delta_s.
_REGRESSORS: dict[str, Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]] = {
    "X_wq": lambda u, w, q, ds: w * q,
    "X_u|u|": lambda u, w, q, ds: u * np.abs(u),
    "X_dsds": lambda u, w, q, ds: u * u * ds * ds,
    "Z_uq": lambda u, w, q, ds: u * q,
    "Z_uu": lambda u, w, q, ds: u * u,
    "Z_uw": lambda u, w, q, ds: u * w,
    "Z_w|w|": lambda u, w, q, ds: w * np.abs(w),
    "Z_ds": lambda u, w, q, ds: u * u * ds,
    "M_q|q|": lambda u, w, q, ds: q * np.abs(q),
    "M_uq": lambda u, w, q, ds: u * q,
    "M_uu": lambda u, w, q, ds: u * u,
    "M_uw": lambda u, w, q, ds: u * w,
    "M_w|w|": lambda u, w, q, ds: w * np.abs(w),
    "M_ds": lambda u, w, q, ds: u * u * ds,
}
#: Smallest peak-to-peak stern-plane motion that can excite the derivatives.
MIN_PLANE_RANGE_RAD = np.radians(1.0)


@dataclass
class Regression:
    """One equation's filtered data: target y and regressors X (columns = ``terms``)."""

    equation: str
    y: np.ndarray
    X: np.ndarray
    terms: tuple[str, ...]


def default_window_s(vehicle: Vehicle) -> float:
    """Filter width: the time the vehicle takes to travel its own length."""
    return vehicle.length_m / vehicle.nominal_speed_m_s


def check_record(record: StateRecord) -> None:
    """Refuse records the identification cannot use, saying what is missing."""
    missing = [c for c in ("u", "w", "q", "theta", "delta_s") if c not in record.states]
    if missing:
        raise BadIdentificationInput(
            f"the record lacks the channels {missing}; it needs u, w, q, theta, delta_s"
        )
    if record.t.size < 50:
        raise BadIdentificationInput(f"the record has only {record.t.size} samples; a zigzag needs hundreds")
    dt = np.diff(record.t)
    if np.any(dt <= 0) or np.ptp(dt) > 0.1 * np.median(dt):
        raise BadIdentificationInput("the samples are not at a steady rate; resample to a fixed rate first")
    for column in STATE_COLUMNS:
        if column in record.states and not np.all(np.isfinite(record[column])):
            raise BadIdentificationInput(f"the channel {column} holds NaN or inf values")
    delta = record["delta_s"]
    if np.ptp(delta) < MIN_PLANE_RANGE_RAD:
        raise BadIdentificationInput(
            f"no stern-plane activity (delta_s spans {np.degrees(np.ptp(delta)):.2f} deg); "
            "identification needs a manoeuvre such as a zigzag"
        )


def weak_form_kernels(window_s: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Sampled h(s) = (1 - s^2)^4 (unit area, times dt) and its time derivative, over ``window_s``."""
    half = max(3, round(0.5 * window_s / dt))
    s = np.arange(-half, half + 1) / half
    h = (1 - s * s) ** 4
    dh = -8 * s * (1 - s * s) ** 3 / (half * dt)
    area = h.sum() * dt
    return h * dt / area, dh * dt / area


def _filter(values: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Kernel * values over the full windows only. With h' as the kernel this is h * d(values)/dt
    (summation by parts: h vanishes at the window edges)."""
    return np.convolve(values, kernel, mode="valid")


def build_regressions(
    records: Sequence[StateRecord],
    vehicle: Vehicle,
    window_s: float | None = None,
    terms: Sequence[str] | None = None,
    fixed: dict[str, float] | None = None,
) -> dict[str, Regression]:
    """Filtered targets and regressors of the three equations, stacked over the records.

    ``terms``: derivatives to estimate (default: the vehicle's non-zero viscous ones); ``fixed``:
    derivatives held at given values, whose contribution moves to the target.
    """
    window_s = default_window_s(vehicle) if window_s is None else window_s
    wanted = tuple(terms) if terms is not None else vehicle.present_terms(VISCOUS_TERMS)
    fixed = dict(fixed or {})
    unknown = (set(wanted) | set(fixed)) - set(VISCOUS_TERMS)
    if unknown:
        raise InputError(f"unknown derivatives {sorted(unknown)}; known: {', '.join(VISCOUS_TERMS)}")
    v = vehicle
    mass, speed, length = v.mass_kg, v.nominal_speed_m_s, v.length_m
    r3, r4, r5 = (v.scale(n) for n in (3, 4, 5))
    names = {eq: tuple(n for n in wanted if TERM_BY_NAME[n].equation == eq) for eq in EQUATIONS}
    rows: dict[str, list] = {eq: [] for eq in EQUATIONS}
    for record in records:
        check_record(record)
        dt = float(np.median(np.diff(record.t)))
        h, dh = weak_form_kernels(window_s, dt)
        if h.size >= record.t.size:
            raise BadIdentificationInput(
                f"the record ({record.t.size} samples) is shorter than the filter window"
            )
        u, w, q, theta, ds = (record[c] for c in ("u", "w", "q", "theta", "delta_s"))
        du, dw, dq = (_filter(x, dh) for x in (u, w, q))
        excess = v.weight_n - v.buoyancy_n
        forces = {
            "X": (mass - r3 * v.coefficient("X_udot")) * du
            + _filter(mass * w * q - v.thrust_n + excess * np.sin(theta), h),
            "Z": (mass - r3 * v.coefficient("Z_wdot")) * dw
            - r4 * v.coefficient("Z_qdot") * dq
            - _filter(mass * u * q + excess * np.cos(theta), h),
            "M": (v.iy_kg_m2 - r5 * v.coefficient("M_qdot")) * dq
            - r4 * v.coefficient("M_wdot") * dw
            + _filter(v.bg_m * v.buoyancy_n * np.sin(theta), h),
        }
        up, wp, qp = u / speed, w / speed, q * length / speed
        for eq in EQUATIONS:
            y = forces[eq] / (v.scale(_EQUATION_POWER[eq]) * speed**2)
            for name, value in fixed.items():
                if TERM_BY_NAME[name].equation == eq:
                    y = y - value * _filter(_REGRESSORS[name](up, wp, qp, ds), h)
            columns = [_filter(_REGRESSORS[n](up, wp, qp, ds), h) for n in names[eq]]
            X = np.column_stack(columns) if columns else np.empty((y.size, 0))
            rows[eq].append((y, X))
    return {
        eq: Regression(
            eq, np.concatenate([r[0] for r in rows[eq]]), np.vstack([r[1] for r in rows[eq]]), names[eq]
        )
        for eq in EQUATIONS
    }


def _with_intercept(X: np.ndarray) -> np.ndarray:
    return np.column_stack([np.ones(X.shape[0]), X])


class LeastSquaresRegressor(EstimatorMixin):
    """Ordinary least squares with intercept; ``std_`` from s^2 (X^T X)^-1 (intercept first in ``cov_``)."""

    def fit(self, X: np.ndarray, y: np.ndarray) -> LeastSquaresRegressor:
        A = _with_intercept(X)
        beta, *_ = np.linalg.lstsq(A, y, rcond=None)
        resid = y - A @ beta
        dof = max(1, y.size - A.shape[1])
        self.cov_ = (resid @ resid / dof) * np.linalg.pinv(A.T @ A)
        self.intercept_, self.coef_ = float(beta[0]), beta[1:]
        self.intercept_std_, self.std_ = float(np.sqrt(self.cov_[0, 0])), np.sqrt(np.diag(self.cov_)[1:])
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        return self.intercept_ + X @ self.coef_


def _ridge_solve(X: np.ndarray, y: np.ndarray, gamma: float) -> tuple[float, np.ndarray]:
    """LS-SVM with a linear kernel in primal form: min ||y - Xw - b||^2 + ||w||^2 / gamma."""
    x_mean, y_mean = X.mean(axis=0), y.mean()
    Xc = X - x_mean
    w = np.linalg.solve(Xc.T @ Xc + np.eye(X.shape[1]) / gamma, Xc.T @ (y - y_mean))
    return float(y_mean - x_mean @ w), w


class LSSVMRegressor(EstimatorMixin):
    """LS-SVM regression with a linear kernel; gamma chosen on held-out data.

    ``gammas``: the candidates (a single value fixes gamma). Held-out data: ``fit(..., validation=(X, y))``
    (e.g. a second manoeuvre), else blocked cross-validation over ``n_folds`` contiguous parts of the
    training data, which keeps neighbouring, strongly correlated samples out of each other's validation set.
    ``cv_errors_``: mean squared held-out error per candidate.
    """

    def __init__(self, gammas: Sequence[float] | float = tuple(np.logspace(-2, 10, 25)), n_folds: int = 5):
        self.gammas = gammas
        self.n_folds = n_folds

    def fit(
        self, X: np.ndarray, y: np.ndarray, validation: tuple[np.ndarray, np.ndarray] | None = None
    ) -> LSSVMRegressor:
        candidates = np.atleast_1d(np.asarray(self.gammas, dtype=float))
        if candidates.size == 1 or X.shape[1] == 0:
            self.gamma_ = float(candidates[-1])
            self.cv_errors_ = np.array([np.nan])
        else:
            splits = (
                [(np.ones(y.size, bool), validation)]
                if validation is not None
                else self._blocked_splits(X, y)
            )
            errors = np.zeros(candidates.size)
            for train, (X_held, y_held) in splits:
                for i, gamma in enumerate(candidates):
                    b, w = _ridge_solve(X[train], y[train], gamma)
                    errors[i] += np.sum((y_held - b - X_held @ w) ** 2)
            self.cv_errors_ = errors / sum(held[1].size for _, held in splits)
            self.gamma_ = float(candidates[int(np.argmin(errors))])
        if X.shape[1]:
            self.intercept_, self.coef_ = _ridge_solve(X, y, self.gamma_)
        else:
            self.intercept_, self.coef_ = float(y.mean()), np.empty(0)
        A = _with_intercept(X)
        resid = y - A @ np.concatenate([[self.intercept_], self.coef_])
        penalty = np.eye(A.shape[1]) / self.gamma_
        penalty[0, 0] = 0.0
        bread = np.linalg.pinv(A.T @ A + penalty)
        s2 = resid @ resid / max(1, y.size - A.shape[1])
        cov = s2 * bread @ (A.T @ A) @ bread
        self.intercept_std_, self.std_ = float(np.sqrt(cov[0, 0])), np.sqrt(np.diag(cov)[1:])
        return self

    def _blocked_splits(self, X: np.ndarray, y: np.ndarray) -> list:
        """(training mask, (X, y) held out) for each contiguous fold."""
        splits = []
        for fold in np.array_split(np.arange(y.size), self.n_folds):
            train = np.ones(y.size, bool)
            train[fold] = False
            splits.append((train, (X[fold], y[fold])))
        return splits

    def predict(self, X: np.ndarray) -> np.ndarray:
        return self.intercept_ + X @ self.coef_


@dataclass
class EquationFit:
    """What one equation's regression gave: derivative values, standard errors, gamma, R^2 of the fit."""

    equation: str
    terms: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    gamma: float | None
    r2: float
    n_samples: int


class SeparateIdentifier(EstimatorMixin):
    """Identify the viscous derivatives one equation at a time (seed 003's separate identification).

    Settings: the vehicle (known mass, inertia, hydrostatics, added mass and the model's term set),
    ``method`` ("lssvm" or "ols"), ``window_s`` of the weak-form filter (None: the time to travel one
    body length), ``terms`` to identify (None: the vehicle's non-zero viscous derivatives), ``fixed``
    derivatives held at given values (e.g. prior values of the insensitive ones); all others are zero.
    Results: ``derivatives_`` and ``std_`` (prime values by name), ``bias_`` and ``bias_std_`` (the
    LS-SVM intercept of each equation), ``equations_`` (EquationFit each).
    """

    def __init__(
        self,
        vehicle: Vehicle,
        method: str = "lssvm",
        window_s: float | None = None,
        terms: Sequence[str] | None = None,
        fixed: dict[str, float] | None = None,
    ):
        self.vehicle = vehicle
        self.method = method
        self.window_s = window_s
        self.terms = terms
        self.fixed = fixed

    def fit(
        self,
        records: StateRecord | Sequence[StateRecord],
        holdout: StateRecord | Sequence[StateRecord] | None = None,
    ) -> SeparateIdentifier:
        """Identify from ``records``; LS-SVM picks gamma on ``holdout`` records if given (OLS ignores it)."""
        if self.method not in ("lssvm", "ols"):
            raise InputError(f"unknown method {self.method!r}; use lssvm or ols")
        regress = partial(
            build_regressions,
            vehicle=self.vehicle,
            window_s=self.window_s,
            terms=self.terms,
            fixed=self.fixed,
        )
        regressions = regress(_as_list(records))
        held_out = regress(_as_list(holdout)) if holdout is not None else None
        self.derivatives_: dict[str, float] = {}
        self.std_: dict[str, float] = {}
        self.bias_: dict[str, float] = {}
        self.bias_std_: dict[str, float] = {}
        self.equations_: dict[str, EquationFit] = {}
        for eq, reg in regressions.items():
            estimator: LSSVMRegressor | LeastSquaresRegressor
            if self.method == "lssvm":
                estimator = LSSVMRegressor().fit(
                    reg.X, reg.y, (held_out[eq].X, held_out[eq].y) if held_out is not None else None
                )
            else:
                estimator = LeastSquaresRegressor().fit(reg.X, reg.y)
            resid = reg.y - estimator.predict(reg.X)
            r2 = 1.0 - float(resid @ resid) / float(np.sum((reg.y - reg.y.mean()) ** 2))
            self.equations_[eq] = EquationFit(
                eq,
                reg.terms,
                estimator.coef_,
                estimator.std_,
                getattr(estimator, "gamma_", None),
                r2,
                reg.y.size,
            )
            self.derivatives_.update(zip(reg.terms, estimator.coef_.tolist(), strict=True))
            self.std_.update(zip(reg.terms, estimator.std_.tolist(), strict=True))
            self.bias_[eq], self.bias_std_[eq] = estimator.intercept_, estimator.intercept_std_
        return self

    def model(self) -> Vehicle:
        """The vehicle with the identified (and fixed) derivatives; the other viscous terms are zero."""
        known = {**(self.fixed or {}), **self.derivatives_}
        identified = {n: known.get(n, 0.0) for n in VISCOUS_TERMS}
        return self.vehicle.with_derivatives(identified, name=f"{self.vehicle.name} (identified)")


def _as_list(records: StateRecord | Sequence[StateRecord]) -> list[StateRecord]:
    return [records] if isinstance(records, StateRecord) else list(records)


def relative_errors(identified: dict[str, float], standard: dict[str, float]) -> dict[str, float]:
    """|identified - standard| / |standard| for every derivative with a non-zero standard value."""
    return {n: abs(v - standard[n]) / abs(standard[n]) for n, v in identified.items() if standard.get(n, 0.0)}
