"""The numba source of every identification kernel: decay integration with exact forward
sensitivities, and the HAC covariance's sums.

The output-error fit needs the simulated angle and rate at the sample instants
*and* their derivatives with respect to every coefficient and the initial
state. Integrating the sensitivity equations alongside the state (fixed-step
RK4, sub-stepped when the step is large against the period) gives a Jacobian
that is exact to the integration error and costs one pass, instead of the
noisy finite differences that stall optimisers (reference §4).

The equation is ``x'' = -sum_j theta_j * phi_j(x, x', u)``. Each term is one
row of the term table (``physics.terms.TERM_TABLE``: name, code, kind, label,
unit) plus one branch of ``term_eval`` giving phi and its partial derivatives
in x, x' and u; adding a term touches nothing else. The input u may itself
depend on parameters (measured channels with their coupling coefficients, a
ringing forcing): their sensitivities are driven by du/dp, given at the samples
(``simulate_with_sensitivities``).

Every simulation is bounded, so that no set of coefficients an optimiser tries can hold a fit:
it stops as soon as the state leaves the range a decay can have (|x| beyond ``MAX_ANGLE_RAD``, a
capsize, or |x'| beyond ``MAX_RATE_RAD_S``, or anything not finite) and refuses outright a call
asking for more than ``MAX_STEPS`` integration steps. Every kernel releases the interpreter lock
(``nogil``): a refit on a worker thread never stops the thread that reads, writes and hears Ctrl-C.

This module holds only kernel code and is imported only to compile it. Callers
go through ``ident.compiled``, which loads the kernels built ahead of time into
a native module (no numba import, about a millisecond) or else this module's
numba JIT (its import and first cached call cost about 0.8 s).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .user_cache import use_user_cache_for_numba

use_user_cache_for_numba()  # numba's cache in the user cache folder, never beside an installed source

#: A decay never leaves +-pi; a simulated state beyond a full turn has diverged (a capsize).
MAX_ANGLE_RAD = 2.0 * math.pi
#: Far beyond any model's rate (a 2 s roll period at 90 deg is 5 rad/s): beyond it, diverged.
MAX_RATE_RAD_S = 1000.0
#: RK4 steps one call may take, (samples - 1) * sub-steps: 4x a 5-minute decay at 400 Hz with 4
#: sub-steps, about a second with 4 terms' sensitivities (``bench/bench_runaway.py``);
#: a call asking more is refused before it starts.
MAX_STEPS = 2_000_000


@numba.njit(cache=True, nogil=True, inline="always")
def term_eval(code: int, x: float, v: float, u: float, eps: float) -> tuple[float, float, float, float]:
    """phi, dphi/dx, dphi/dv, dphi/du of one term at the state (x, v) and input u."""
    if code == 0:
        return v, 0.0, 1.0, 0.0
    if code == 1:
        return abs(v) * v, 0.0, 2.0 * abs(v), 0.0
    if code == 2:
        return v * v * v, 0.0, 3.0 * v * v, 0.0
    if code == 3:
        return x, 1.0, 0.0, 0.0
    if code == 4:
        return x * x, 2.0 * x, 0.0, 0.0
    if code == 5:
        return x * x * x, 3.0 * x * x, 0.0, 0.0
    s = math.sin(x)
    if code == 6:
        return s, math.cos(x), 0.0, 0.0
    if code == 7:
        return s * s, 2.0 * s * math.cos(x), 0.0, 0.0
    if code == 8:
        return s * s * s, 3.0 * s * s * math.cos(x), 0.0, 0.0
    if code == 9:
        th = math.tanh(v / eps)
        return th, 0.0, (1.0 - th * th) / eps, 0.0
    if code == 10:
        return u, 0.0, 0.0, 1.0
    return math.nan, math.nan, math.nan, math.nan


@numba.njit(cache=True, nogil=True)
def term_matrix(codes: np.ndarray, x: np.ndarray, v: np.ndarray, u: np.ndarray, eps: float) -> np.ndarray:
    """Regressor matrix phi_j(x_i, v_i, u_i), shape (n, len(codes)): x'' = -phi @ theta."""
    out = np.empty((x.size, codes.size))
    for i in range(x.size):
        for j in range(codes.size):
            out[i, j] = term_eval(codes[j], x[i], v[i], u[i], eps)[0]
    return out


@numba.njit(cache=True, nogil=True)
def acceleration_partials(
    codes: np.ndarray, theta: np.ndarray, x: np.ndarray, v: np.ndarray, u: np.ndarray, eps: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """x'' and its partials in x, x', u and theta at every sample: what a lagged observation needs."""
    n = x.size
    acc = np.zeros(n)
    acc_x = np.zeros(n)
    acc_v = np.zeros(n)
    acc_u = np.zeros(n)
    phi = np.empty((n, codes.size))
    for i in range(n):
        for j in range(codes.size):
            value, dx, dv, du = term_eval(codes[j], x[i], v[i], u[i], eps)
            phi[i, j] = value
            acc[i] -= theta[j] * value
            acc_x[i] -= theta[j] * dx
            acc_v[i] -= theta[j] * dv
            acc_u[i] -= theta[j] * du
    return acc, acc_x, acc_v, acc_u, phi


@numba.njit(cache=True, nogil=True, inline="always")
def _deriv(
    z: np.ndarray,
    dz: np.ndarray,
    theta: np.ndarray,
    codes: np.ndarray,
    u: float,
    du_dp: np.ndarray,
    eps: float,
) -> None:
    """Time derivative of the state and its sensitivities (theta, then x0, v0, then the input's)."""
    x = z[0]
    v = z[1]
    acc = 0.0
    ax = 0.0
    av = 0.0
    au = 0.0
    n_theta = codes.size
    n_par = (z.size - 2) // 2
    for j in range(n_theta):
        phi, phx, phv, phu = term_eval(codes[j], x, v, u, eps)
        acc -= theta[j] * phi
        ax -= theta[j] * phx
        av -= theta[j] * phv
        au -= theta[j] * phu
        dz[2 + 2 * j + 1] = -phi
    for k in range(du_dp.size):
        dz[3 + 2 * (n_theta + 2 + k)] = au * du_dp[k]
    dz[0] = v
    dz[1] = acc
    for p in range(n_par):
        sx = z[2 + 2 * p]
        sv = z[3 + 2 * p]
        dz[2 + 2 * p] = sv
        forcing = 0.0 if n_theta <= p < n_theta + 2 else dz[3 + 2 * p]
        dz[3 + 2 * p] = ax * sx + av * sv + forcing


@numba.njit(cache=True, nogil=True, inline="always")
def _state_sane(x: float, v: float) -> bool:
    """A state a decay can have (False for NaN too)."""
    return abs(x) <= MAX_ANGLE_RAD and abs(v) <= MAX_RATE_RAD_S


@numba.njit(cache=True, nogil=True, inline="always")
def _sane(z: np.ndarray) -> bool:
    """State within range and every sensitivity finite (an element loop: no array per sample)."""
    if not _state_sane(z[0], z[1]):
        return False
    for m in range(z.size):  # noqa: SIM110 (numba compiles no generator inside all())
        if not math.isfinite(z[m]):
            return False
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def _rk4_step(
    z: np.ndarray,
    h: float,
    theta: np.ndarray,
    codes: np.ndarray,
    u0: float,
    du: float,
    g: np.ndarray,
    eps: float,
    k: np.ndarray,
    tmp: np.ndarray,
) -> None:
    """One RK4 step of the state and its sensitivities, in place; the input goes u0 -> u0 + du and its
    partials g[0] -> g[2] (g[1] halfway). k (4, z.size) and tmp are work arrays, so no step allocates.

    The four stages are one loop around one ``_deriv``: numba inlines its IR (and ``term_eval``'s) once
    here, not four times as when the stages were written out, which cost nearly a third of the native build's
    CPU (``bench/bench_kernel_build.py``) and ran no faster.
    """
    size = z.size
    for m in range(size):
        tmp[m] = z[m]
    for stage in range(4):
        u = u0 if stage == 0 else (u0 + 0.5 * du if stage < 3 else u0 + du)
        _deriv(tmp, k[stage], theta, codes, u, g[(stage + 1) // 2], eps)
        if stage < 3:
            step = 0.5 * h if stage < 2 else h
            for m in range(size):
                tmp[m] = z[m] + step * k[stage, m]
    for m in range(size):
        z[m] += h / 6.0 * (k[0, m] + 2.0 * k[1, m] + 2.0 * k[2, m] + k[3, m])


@numba.njit(cache=True, nogil=True)
def simulate_with_sensitivities(
    t: np.ndarray,
    x0: float,
    v0: float,
    theta: np.ndarray,
    codes: np.ndarray,
    u: np.ndarray,
    du_dp: np.ndarray,
    eps: float,
    n_sub: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Angle, rate and their sensitivities at every t, integrating from (x0, v0) at t[0].

    Returns ``(x, v, sx, sv, ok)`` with ``sx[i, p] = dx(t_i)/dp`` for p over
    theta, then x0, v0, then the m parameters of the input whose partials
    ``du_dp`` (n, m) are given at the samples. ``u`` is the exogenous input at
    the sample times, linear inside a step (and so are its partials). ``ok`` is
    False when the solution left any sane range (``_sane``) or the call asks for
    more than ``MAX_STEPS`` steps: the integration stops there and the rest is
    filled with the last sane values (zeros before any), always finite, so an
    optimiser can back off.
    """
    n = t.size
    n_theta = codes.size
    n_in = du_dp.shape[1]
    n_par = n_theta + 2 + n_in
    size = 2 + 2 * n_par
    z = np.zeros(size)
    z[0] = x0
    z[1] = v0
    z[2 + 2 * n_theta] = 1.0  # dx/dx0
    z[3 + 2 * (n_theta + 1)] = 1.0  # dv/dv0
    k = np.empty((4, size))
    tmp = np.empty(size)
    g = np.empty((3, n_in))  # the input's partials at the step's start, middle and end
    xs = np.empty(n)
    vs = np.empty(n)
    sx = np.empty((n, n_par))
    sv = np.empty((n, n_par))
    ok = n_sub >= 1 and (n - 1) * n_sub <= MAX_STEPS and _sane(z)
    for i in range(n):
        if i > 0 and ok:
            h = (t[i] - t[i - 1]) / n_sub
            du = (u[i] - u[i - 1]) / n_sub
            for s in range(n_sub):
                u0 = u[i - 1] + s * du
                for q in range(n_in):
                    dg = (du_dp[i, q] - du_dp[i - 1, q]) / n_sub
                    g[0, q] = du_dp[i - 1, q] + s * dg
                    g[1, q] = g[0, q] + 0.5 * dg
                    g[2, q] = g[0, q] + dg
                _rk4_step(z, h, theta, codes, u0, du, g, eps, k, tmp)
            ok = _sane(z)
        if ok:
            xs[i] = z[0]
            vs[i] = z[1]
            for p in range(n_par):
                sx[i, p] = z[2 + 2 * p]
                sv[i, p] = z[3 + 2 * p]
        else:
            xs[i] = xs[i - 1] if i > 0 else 0.0
            vs[i] = vs[i - 1] if i > 0 else 0.0
            sx[i, :] = 0.0
            sv[i, :] = 0.0
    return xs, vs, sx, sv, ok


@numba.njit(cache=True, nogil=True)
def simulate(
    t: np.ndarray,
    x0: float,
    v0: float,
    theta: np.ndarray,
    codes: np.ndarray,
    u: np.ndarray,
    eps: float,
    n_sub: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Angle and rate only (RK4 without sensitivities): prediction and plotting.

    NaN from the first sample where the state left the range a decay can have (``_state_sane``):
    a prediction that diverged is no number, and it stops there. All NaN past x0 when the call
    asks for more than ``MAX_STEPS`` steps.
    """
    n = t.size
    xs = np.full(n, np.nan)
    vs = np.full(n, np.nan)
    x = x0
    v = v0
    if n == 0:
        return xs, vs
    xs[0] = x
    vs[0] = v
    if n_sub < 1 or (n - 1) * n_sub > MAX_STEPS:
        return xs, vs
    for i in range(1, n):
        h = (t[i] - t[i - 1]) / n_sub
        du = (u[i] - u[i - 1]) / n_sub
        for s in range(n_sub):
            u0 = u[i - 1] + s * du
            x, v = _rk4_state_step(x, v, h, theta, codes, u0, du, eps)
        if not _state_sane(x, v):
            break
        xs[i] = x
        vs[i] = v
    return xs, vs


@numba.njit(cache=True, nogil=True, inline="always")
def _acc(x: float, v: float, theta: np.ndarray, codes: np.ndarray, u: float, eps: float) -> float:
    acc = 0.0
    for j in range(codes.size):
        acc -= theta[j] * term_eval(codes[j], x, v, u, eps)[0]
    return acc


@numba.njit(cache=True, nogil=True, inline="always")
def _rk4_state_step(
    x: float, v: float, h: float, theta: np.ndarray, codes: np.ndarray, u0: float, du: float, eps: float
) -> tuple[float, float]:
    """One RK4 step of the state alone: as ``_rk4_step``, its four stages are one loop around one ``_acc``."""
    xs = x
    vs = v
    sum_v = v
    sum_a = 0.0
    for stage in range(4):
        u = u0 if stage == 0 else (u0 + 0.5 * du if stage < 3 else u0 + du)
        a = _acc(xs, vs, theta, codes, u, eps)
        if stage == 0:
            sum_a = a
        else:  # the weights 2, 2, 1 summed in the order (v + 2 v2 + 2 v3 + v4): the same bits as written out
            weight = 2.0 if stage < 3 else 1.0
            sum_v += weight * vs
            sum_a += weight * a
        if stage < 3:
            step = 0.5 * h if stage < 2 else h
            xs = x + step * vs
            vs = v + step * a
    return x + h / 6.0 * sum_v, v + h / 6.0 * sum_a


@numba.njit(cache=True, nogil=True)
def _box_full(x: np.ndarray, width: int) -> np.ndarray:
    """Full convolution of each column of x (n, k) with a boxcar of ``width`` ones.

    Element loops, not row operations: numba compiles a row assignment (``out[t] = acc``) with its
    shape-mismatch error message, about a tenth of the native build's CPU for that one line.
    """
    n, k = x.shape
    out = np.zeros((n + width - 1, k))
    acc = np.zeros(k)
    for t in range(n + width - 1):
        for c in range(k):
            if t < n:
                acc[c] += x[t, c]
            if t >= width:
                acc[c] -= x[t - width, c]
            out[t, c] = acc[c]
    return out


@numba.njit(cache=True, nogil=True)
def triangle_smooth(x: np.ndarray, bandwidth: int) -> np.ndarray:
    """sum_s w(|t-s|) x_s with Bartlett weights w(l) = 1 - l/(L+1), |l| <= L, down the rows of x (n, k).

    The triangle is two boxcars of L+1 samples convolved: O(n k) whatever the bandwidth.
    """
    width = bandwidth + 1
    return _box_full(_box_full(x, width), width)[bandwidth : bandwidth + x.shape[0]] / width


@numba.njit(cache=True, nogil=True)
def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a' b for (n, p) columns, as loops: BLAS is not there for the ahead-of-time build."""
    n, p = a.shape
    out = np.zeros((p, b.shape[1]))
    for t in range(n):
        for i in range(p):
            ai = a[t, i]
            for j in range(b.shape[1]):
                out[i, j] += ai * b[t, j]
    return out


@numba.njit(cache=True, nogil=True)
def hac_meat(
    jac: np.ndarray, res: np.ndarray, bread: np.ndarray, bandwidth: int, correct: bool
) -> np.ndarray:
    """One run's HAC meat: sum_t g_t (smoothed g)_t' plus, if ``correct``, sum_t M_t A^-1 K_t.

    ``jac`` (outputs, n, p) and ``res`` (outputs, n) are noise-weighted.
    """
    n_out, n, p = jac.shape
    g = np.zeros((n, p))
    for o in range(n_out):
        for t in range(n):
            for a in range(p):
                g[t, a] += jac[o, t, a] * res[o, t]
    meat = _cross(g, triangle_smooth(g, bandwidth))
    if correct:
        meat += _bias_correction(jac, bread, bandwidth)
    return meat


@numba.njit(cache=True, nogil=True, inline="always")
def _add_information(jac: np.ndarray, t: int, sign: float, acc: np.ndarray) -> None:
    """acc += sign * M_t, the information of instant t (p*p, row-major), summed over the outputs."""
    n_out, _, p = jac.shape
    for o in range(n_out):
        for a in range(p):
            for b in range(p):
                acc[a * p + b] += sign * jac[o, t, a] * jac[o, t, b]


@numba.njit(cache=True, nogil=True)
def _bias_correction(jac: np.ndarray, bread: np.ndarray, bandwidth: int) -> np.ndarray:
    """sum_t M_t A^-1 K_t, with K_t = triangle_smooth(M)_t computed as a stream.

    The same two running boxcars as ``triangle_smooth``, but row by row with a
    ring of the last L+1 first-boxcar rows: the (n, p*p) information arrays are
    never built (allocating them cost more in page faults than all the arithmetic).
    """
    n_out, n, p = jac.shape
    width = bandwidth + 1
    first = np.zeros(p * p)  # running boxcar over M
    second = np.zeros(p * p)  # running boxcar over the first one
    ring = np.zeros((width, p * p))  # the last ``width`` rows of the first boxcar
    spread = np.zeros(p)
    meat = np.zeros((p, p))
    for t in range(n + bandwidth):
        if t < n:
            _add_information(jac, t, 1.0, first)
        if t >= width:
            _add_information(jac, t - width, -1.0, first)
        slot = t % width
        for m in range(p * p):
            second[m] += first[m]
            if t >= width:
                second[m] -= ring[slot, m]
            ring[slot, m] = first[m]
        i = t - bandwidth  # the instant whose smoothed information K_i = second / width is complete
        if i < 0:
            continue
        for o in range(n_out):
            for c in range(p):  # (bread @ jac[o, i])': bread is symmetric
                s = 0.0
                for d in range(p):
                    s += jac[o, i, d] * bread[d, c]
                spread[c] = s
            for b in range(p):
                w = 0.0  # (bread @ jac[o, i]) @ K_i, one column at a time
                for c in range(p):
                    w += spread[c] * (second[c * p + b] / width)
                for a in range(p):
                    meat[a, b] += jac[o, i, a] * w
    return meat
