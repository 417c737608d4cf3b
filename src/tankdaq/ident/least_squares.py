"""Levenberg-Marquardt for the output-error fit, in numpy alone.

scipy.optimize costs about 0.4 s to import (it pulls linprog, scipy.linalg, scipy.special, ...), a
third of a whole ``tankdaq replay``; the fit needs only this. It follows MINPACK's lmder (Moré 1978,
"The Levenberg-Marquardt algorithm: implementation and theory"), the engine behind
``scipy.optimize.least_squares(method="lm", x_scale="jac")``, which the tests compare it against:

- a trust region on the scaled step ``||D p|| <= delta``, with Marquardt's scaling ``D`` the Jacobian's
  column norms kept as a running maximum (a parameter's scale never shrinks back: no oscillation);
- one QR of the Jacobian per accepted point (R of ``[J f]``: Q'f is its last column, Q is never
  formed). Every damped step solves ``(J'J + par D^2) p = -J'f`` in closed form from the SVD of the
  small triangle ``R D^-1`` (p x p), so a trial costs O(p^2) beside its residual evaluation, and a
  rank-deficient Jacobian needs no column pivoting (which numpy's QR lacks);
- the damping ``par`` found as in MINPACK's lmpar: Newton's method on ``1/||D p|| = 1/delta``, kept
  within bounds, accurate to 10 %;
- a step kept when the actual reduction is at least 1e-4 of the predicted one; the radius shrinks on a
  poor ratio (by a quadratic fit to the directional derivative) and doubles on a good one;
- MINPACK's stopping tests: ``ftol`` on both the actual and the predicted relative reduction of the
  sum of squares (with ratio <= 2), ``xtol`` on the radius against the scaled ``||D x||``, ``gtol``
  on the largest cosine between the residuals and a Jacobian column, and ``max_nfev`` evaluations.

Residuals that are not finite (a simulation that diverged) or far larger than the current ones (a
penalty) count as no reduction at all: the step is refused and the radius shrinks tenfold.

A solve may be given a budget (``solve_budget``: a deadline and a cancel flag, for the solves this
thread runs inside the block): it is checked before every evaluation, and a solve past it raises
``FitAbandoned``. A thread cannot be killed; with the kernels bounded (``ident.kernels``) this
abandons a runaway fit at most one evaluation past its budget.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field

import numpy as np

from ..errors import IdentificationError

#: ``status`` as scipy.optimize.least_squares reports it.
STATUS_MESSAGES = {
    0: "the number of evaluations reached max_nfev",
    1: "gtol: the residuals are orthogonal to the Jacobian's columns",
    2: "ftol: the relative reduction of the sum of squares is below ftol",
    3: "xtol: the relative step is below xtol",
    4: "ftol and xtol are both satisfied",
}
#: The initial radius relative to ``||D x0||`` (MINPACK's ``factor``, scipy's choice).
_FACTOR = 100.0
_EPS = float(np.finfo(float).eps)
_TINY = float(np.finfo(float).tiny)

Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


class FitAbandoned(IdentificationError):
    """A solve ran past its budget or was cancelled (``solve_budget``)."""


@dataclass
class SolveBudget:
    """How long the solves inside ``solve_budget`` may compute, and the flag that cancels them at once.

    The budget is the solving thread's CPU time, not the wall clock: a fit on a busy PC (another program,
    a viewer) is slower, not a runaway, and keeps its result; a runaway computes, and is stopped at the
    same point on any machine load.
    """

    seconds: float
    cancel: threading.Event = field(default_factory=threading.Event)
    started: float = field(default_factory=time.thread_time)  # made on the thread that solves
    abandoned: bool = False  # a solve was stopped by this budget

    def check(self) -> None:
        """Raise ``FitAbandoned`` past the budget or once cancelled."""
        computed = time.thread_time() - self.started
        if self.cancel.is_set() or computed > self.seconds:
            self.abandoned = True
            why = "cancelled" if self.cancel.is_set() else f"past its budget of {self.seconds:g} s"
            raise FitAbandoned(f"the fit was abandoned after {computed:.1f} s of computing ({why})")


_BUDGET: ContextVar[SolveBudget | None] = ContextVar("tankdaq_solve_budget", default=None)


@contextlib.contextmanager
def solve_budget(seconds: float, cancel: threading.Event | None = None) -> Iterator[SolveBudget]:
    """Every solve this thread runs inside the block stops past ``seconds`` or once ``cancel`` is set.

    A context variable, so that the fits between (``OutputErrorFit``, ``OnlineIdentifier``) need no
    setting: the caller that owns the thread (``BackgroundFit``) decides how long its fits may run.
    """
    budget = SolveBudget(seconds, cancel if cancel is not None else threading.Event())
    token = _BUDGET.set(budget)
    try:
        yield budget
    finally:
        _BUDGET.reset(token)


def _check_budget() -> None:
    budget = _BUDGET.get()
    if budget is not None:
        budget.check()


@dataclass(frozen=True)
class LeastSquaresResult:
    """The best point found, its cost ``0.5 * ||f||^2``, evaluations used, and why it stopped."""

    x: np.ndarray
    cost: float
    nfev: int
    status: int
    message: str


def levenberg_marquardt(
    evaluate: Evaluate,
    x0: np.ndarray,
    *,
    xtol: float = 1e-8,
    ftol: float = 1e-8,
    gtol: float = 1e-8,
    max_nfev: int = 200,
) -> LeastSquaresResult:
    """Minimise ``||f(x)||^2``; ``evaluate(x)`` returns ``(f, J)`` together (one simulation gives both).

    Each call counts as one evaluation (``nfev``), the Jacobian of a refused trial is simply unused.
    Tolerances as in scipy.optimize.least_squares(method="lm", x_scale="jac"). Raises
    ``FitAbandoned`` before an evaluation past the budget of an enclosing ``solve_budget``.
    """
    x = np.array(x0, dtype=float)
    _check_budget()
    f, jac = evaluate(x)
    nfev = 1
    fnorm = float(np.linalg.norm(f))
    if not np.isfinite(fnorm) or not np.all(np.isfinite(jac)):
        # an identification failure (a live refit skips it), not a crash: the model diverges from here
        raise IdentificationError(
            "the model diverges from its starting point (residuals or Jacobian not finite); "
            "try a simpler model"
        )
    col_norms = np.linalg.norm(jac, axis=0)
    scale = np.where(col_norms > 0.0, col_norms, 1.0)
    xnorm = float(np.linalg.norm(scale * x))
    delta = _FACTOR * xnorm or _FACTOR
    par = 0.0
    first = True  # until a step is accepted the radius also shrinks to the first step
    while True:
        # R of [J f] holds J's R and Q'f in its last column: Q itself (n x p) is never formed,
        # five times cheaper than np.linalg.qr(jac) and the one tall operation of a step.
        r_aug = np.asarray(np.linalg.qr(np.column_stack([jac, f]), mode="r"))  # asarray: the stubs say tuple
        p = jac.shape[1]
        r, qtf = r_aug[:p, :p], r_aug[:p, p]
        col_norms = np.linalg.norm(jac, axis=0)
        if fnorm == 0.0 or _largest_cosine(r, qtf, fnorm, col_norms) <= gtol:
            return _result(x, fnorm, nfev, 1)
        scale = np.maximum(scale, col_norms)
        u, sv, vt = np.linalg.svd(r / scale, full_matrices=False)
        g = u.T @ qtf
        while True:  # trials from this Jacobian until one is accepted
            par, c = _damping(sv, g, delta, par)
            step = -(vt.T @ c) / scale
            pnorm = float(np.linalg.norm(c))  # ||D step||
            if first:
                delta = min(delta, pnorm)
            trial = x + step
            _check_budget()
            f_trial, jac_trial = evaluate(trial)
            nfev += 1
            fnorm_trial = float(np.linalg.norm(f_trial))
            if not np.isfinite(fnorm_trial) or not np.all(np.isfinite(jac_trial)):
                fnorm_trial = np.inf
            worse = 0.1 * fnorm_trial >= fnorm  # refused outright: no reduction to speak of
            jstep_norm = float(np.linalg.norm(sv * c))  # ||J step||
            actual, predicted, slope = _reductions(fnorm, fnorm_trial, worse, jstep_norm, par, pnorm)
            ratio = actual / predicted if predicted != 0.0 else 0.0
            delta, par = _new_radius(ratio, actual, slope, worse, delta, par, pnorm)
            accepted = ratio >= 1e-4
            if accepted:
                x, f, jac, fnorm = trial, f_trial, jac_trial, fnorm_trial
                xnorm = float(np.linalg.norm(scale * x))
                first = False
            f_converged = abs(actual) <= ftol and predicted <= ftol and ratio <= 2.0
            x_converged = delta <= xtol * xnorm
            if f_converged or x_converged:
                return _result(x, fnorm, nfev, 4 if f_converged and x_converged else 2 if f_converged else 3)
            if nfev >= max_nfev:
                return _result(x, fnorm, nfev, 0)
            if accepted:
                break


def _reductions(
    fnorm: float, fnorm_trial: float, worse: bool, jstep_norm: float, par: float, pnorm: float
) -> tuple[float, float, float]:
    """A trial's actual and predicted relative reductions of the sum of squares, and the model's slope.

    A trial far ``worse`` than the current point (a diverged simulation, a penalty) reduces by -1.
    """
    actual = -1.0 if worse else 1.0 - (fnorm_trial / fnorm) ** 2
    model = (jstep_norm / fnorm) ** 2  # ||J step||^2 / ||f||^2
    damped = par * (pnorm / fnorm) ** 2
    return actual, model + 2.0 * damped, -(model + damped)  # slope: the directional derivative


def _new_radius(
    ratio: float, actual: float, slope: float, worse: bool, delta: float, par: float, pnorm: float
) -> tuple[float, float]:
    """The trust radius and damping after a trial (MINPACK's lmder): shrunk on a poor ratio, by a
    quadratic fit to the directional derivative, tenfold when refused; doubled on a good one."""
    if ratio <= 0.25:
        shrink = 0.5 if actual >= 0.0 else 0.5 * slope / (slope + 0.5 * actual)
        if worse or shrink < 0.1:
            shrink = 0.1
        return shrink * min(delta, pnorm / 0.1), par / shrink
    if par == 0.0 or ratio >= 0.75:
        return pnorm / 0.5, par * 0.5
    return delta, par


def _largest_cosine(r: np.ndarray, qtf: np.ndarray, fnorm: float, col_norms: np.ndarray) -> float:
    """max_j |J_j . f| / (||J_j|| ||f||): zero at a stationary point, whatever the scales."""
    cosines = np.abs(r.T @ qtf) / fnorm
    nonzero = col_norms > 0.0
    return float(np.max(cosines[nonzero] / col_norms[nonzero], initial=0.0))


def _damping(sv: np.ndarray, g: np.ndarray, delta: float, par: float) -> tuple[float, np.ndarray]:
    """MINPACK's lmpar in the SVD basis: the damping ``par`` and the scaled step as ``-V' D p``.

    With ``R D^-1 = U S V'`` and ``g = U' Q' f`` the damped scaled step is ``c = S g / (S^2 + par)``; par
    is 0 when the Gauss-Newton step fits in the radius, else ``||c|| = delta`` within 10 % by Newton's
    method on ``1/||c||`` (converges fast: nearly linear in par), safeguarded by the bounds
    ``[parl, paru]``. ``par`` on entry is the previous value, a good first guess.
    """
    nonsingular = sv > sv[0] * _EPS * sv.size
    gauss_newton = np.where(nonsingular, g / np.where(nonsingular, sv, 1.0), 0.0)
    norm = float(np.linalg.norm(gauss_newton))
    excess = norm - delta
    if excess <= 0.1 * delta:
        return 0.0, gauss_newton

    def newton_correction(c: np.ndarray, damping: float) -> float:
        """(||c|| - delta) / (delta * w), w = c' (S^2 + par)^-1 c / ||c||^2: MINPACK's parc."""
        c_norm = float(np.linalg.norm(c))
        inverse = c / np.sqrt(sv**2 + damping)  # damping 0: only asked when every sv > 0
        weight = float(inverse @ inverse) / c_norm**2
        return (c_norm - delta) / (delta * weight)

    lower = newton_correction(gauss_newton, 0.0) if np.all(nonsingular) else 0.0
    gradient_norm = float(np.linalg.norm(sv * g))
    upper = gradient_norm / delta or _TINY / min(delta, 0.1)
    par = min(max(par, lower), upper)
    if par == 0.0:
        par = gradient_norm / norm
    for iteration in range(10):
        if par == 0.0:
            par = max(_TINY, 0.001 * upper)
        c = sv * g / (sv**2 + par)
        previous, excess = excess, float(np.linalg.norm(c)) - delta
        stalled = lower == 0.0 and previous < 0.0 and excess <= previous  # rank-deficient: no better
        if abs(excess) <= 0.1 * delta or stalled or iteration == 9:
            return par, c
        if excess > 0.0:
            lower = max(lower, par)
        elif excess < 0.0:
            upper = min(upper, par)
        par = max(lower, par + newton_correction(c, par))
    raise AssertionError("unreachable: the loop returns at its tenth iteration")


def _result(x: np.ndarray, fnorm: float, nfev: int, status: int) -> LeastSquaresResult:
    return LeastSquaresResult(x, 0.5 * fnorm**2, nfev, status, STATUS_MESSAGES[status])
