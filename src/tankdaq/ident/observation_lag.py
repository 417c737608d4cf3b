"""The observation lag of an output-error fit, x(t - lag), as a linear map of the simulated state.

Kept apart from the estimator because it is plain interpolation algebra: being linear in x and
x', the same map carries the sensitivities, so the fit's Jacobian stays exact.
"""

from __future__ import annotations

import numpy as np

from .compiled import acceleration_partials
from .forcing import Forcing


class LagOperator:
    """x(t - lag) on the grid t from the simulated x and x' there: a linear map, so sensitivities follow.

    Inside the grid a cubic Hermite interpolation (error ~ (omega h)^4, whatever
    the lag); beyond the ends a second-order Taylor step from the end sample,
    x + d x' + d^2/2 x'' with d = (t - lag) - t_end, using the model's x''.
    """

    def __init__(self, t: np.ndarray, lag: float) -> None:
        n = t.size
        s = t - lag
        i = np.clip(np.searchsorted(t, s) - 1, 0, n - 2)
        h = t[i + 1] - t[i]
        u = (s - t[i]) / h
        self.lo, self.hi = i, i + 1
        # weights of x[lo], h x'[lo], x[hi], h x'[hi] and their derivatives in the lag (ds/dlag = -1)
        self.w = [
            (1 + 2 * u) * (1 - u) ** 2,
            h * u * (1 - u) ** 2,
            u * u * (3 - 2 * u),
            h * u * u * (u - 1),
        ]
        self.dw = [
            -(6 * u * u - 6 * u) / h,
            -(3 * u * u - 4 * u + 1),
            -(6 * u - 6 * u * u) / h,
            -(3 * u * u - 2 * u),
        ]
        self.wa = np.zeros(n)
        self.dwa = np.zeros(n)
        self.end = np.zeros(n, dtype=int)  # 0: first sample's x'', 1: last sample's
        for end, outside in ((0, s < t[0]), (-1, s > t[-1])):
            if not np.any(outside):
                continue
            d = s[outside] - t[end]
            self.lo[outside] = self.hi[outside] = end % n
            self.w[0][outside], self.w[1][outside] = 1.0, d
            self.w[2][outside], self.w[3][outside] = 0.0, 0.0
            self.dw[0][outside], self.dw[1][outside] = 0.0, -1.0
            self.dw[2][outside], self.dw[3][outside] = 0.0, 0.0
            self.wa[outside], self.dwa[outside] = 0.5 * d * d, -d
            self.end[outside] = 0 if end == 0 else 1

    def _combine(
        self, w: list[np.ndarray], wa: np.ndarray, x: np.ndarray, v: np.ndarray, acc: np.ndarray
    ) -> np.ndarray:
        def col(weight: np.ndarray) -> np.ndarray:
            return weight if x.ndim == 1 else weight[:, None]

        return (
            col(w[0]) * x[self.lo]
            + col(w[1]) * v[self.lo]
            + col(w[2]) * x[self.hi]
            + col(w[3]) * v[self.hi]
            + col(wa) * acc[self.end]
        )

    def apply(self, x: np.ndarray, v: np.ndarray, acc_ends: np.ndarray) -> np.ndarray:
        """x(t - lag) from x, x' on the grid (or their sensitivities, one column per parameter)."""
        return self._combine(self.w, self.wa, x, v, acc_ends)

    def apply_lag_derivative(self, x: np.ndarray, v: np.ndarray, acc_ends: np.ndarray) -> np.ndarray:
        """d x(t - lag) / d lag."""
        return self._combine(self.dw, self.dwa, x, v, acc_ends)


def end_accelerations(
    codes: np.ndarray, theta: np.ndarray, x: np.ndarray, v: np.ndarray, forcing: Forcing, friction_eps: float
) -> np.ndarray:
    """x'' at the first and last instant: where the lagged angle leaves the simulated span."""
    ends = [0, -1]
    return acceleration_partials(codes, theta, x[ends], v[ends], forcing.u[ends], friction_eps)[0]


def end_acceleration_sensitivities(
    codes: np.ndarray,
    theta: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    forcing: Forcing,
    sx: np.ndarray,
    sv: np.ndarray,
    kernel_cols: list[int],
    friction_eps: float,
) -> tuple[np.ndarray, np.ndarray]:
    """x'' at both ends and its derivative in every kernel parameter (through state, theta, input)."""
    ends = [0, -1]
    acc, acc_x, acc_v, acc_u, phi = acceleration_partials(
        codes, theta, x[ends], v[ends], forcing.u[ends], friction_eps
    )
    s_acc = acc_x[:, None] * sx[ends] + acc_v[:, None] * sv[ends]
    s_acc[:, : theta.size] -= phi
    s_acc[:, theta.size + 2 :] += acc_u[:, None] * forcing.partials[ends]
    return acc, s_acc[:, kernel_cols]
