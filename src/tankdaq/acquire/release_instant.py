"""Where the release happened: the hand's held motion before a candidate instant and the decay equation
after it, fitted jointly to angle and rate; the instant that explains both best is the release.

``acquire.release.ReleaseDetector`` decides *whether* a release happened; ``find_release_instant`` then
scans candidate instants through this fit, which answers for each how well (``sse``), with what state
(``state_at``) and how sure (``instant_se``; the 95 % interval is ``COVERAGE_FACTOR`` of it). A hand that
sways (the rate at release not zero) is followed by a cubic spline rather than one cubic, where the data
ask for it.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

#: The 95 % interval is this many standard errors either side. The standard error from the profile's
#: curvature assumes the hold and decay models are exact; they are not quite (a sway is followed by a
#: spline, the decay by a cubic equation): from a swaying hold 1.96 of them covered the truth in only
#: 74-82 % of releases. The factor is calibrated on the simulator, not derived: 3 of them (with the floor of
#: ``instant_se``) cover 95.0, 95.5 and 94.0 % of 200 releases from a swaying hold at 100, 200 and 400 Hz,
#: and all of a still hold's, where the interval is wider than it need be (bench/results/release_sway.json).
COVERAGE_FACTOR = 3.0
#: The profile's curvature is read over at least this (s) either side: over +-2 samples at 200 or 400 Hz
#: it sees only the bottom of a profile that the sway's spline flattens further out.
CURVATURE_STEP_S = 0.02


@dataclass(frozen=True)
class ReleaseInstant:
    """The instant found (device s), its standard error, the half-width of its 95 % interval
    (``COVERAGE_FACTOR`` standard errors), and the state the decay starts from there."""

    t_s: float
    se_s: float
    angle_rad: float
    rate_rad_s: float

    @property
    def u95_s(self) -> float:
        return COVERAGE_FACTOR * self.se_s


def find_release_instant(
    t: np.ndarray,
    angle: np.ndarray,
    rate: np.ndarray,
    hold: int,
    rest_rad: float,
    scan: range,
    dt: float,
) -> ReleaseInstant:
    """The instant that explains the held motion before it and the decay after it best.

    ``hold`` is the sample where the model left the hold, ``dt`` the sample interval (s). Scanned over
    the samples ``scan`` names, then refined down to a quarter sample, with the asymmetric restoring
    term c2 kept only where the data ask for it.
    """
    full, symmetric = (ReleaseInstantFit(t, angle, rate, hold, rest_rad=rest_rad, asymmetric=asymmetric)
                       for asymmetric in (True, False))  # fmt: skip
    earliest = float(t[2])
    tau = min((float(t[k]) for k in scan), key=full.sse)  # a sway moves it by 20 ms at most: refined below
    swaying = full.with_knots(SWAY_KNOTS_S)
    # Each freedom only where it earns its place (BIC on noise-weighted rows). The hand's sway: a still
    # hold's cubic is the more precise, but a hand that sways a few tenths of a degree at 1-3 Hz bends
    # it, and the instant with it, by up to 20 ms. c2: when the hull is nearly symmetric it is almost
    # collinear with k0 and the odd terms over one swing, and its noise costs the instant.
    penalty = math.log(full.y.size)
    if full.sse(tau) - swaying.sse(tau) > len(SWAY_KNOTS_S) * penalty:
        full, symmetric = swaying, symmetric.with_knots(SWAY_KNOTS_S)
    physics = full if symmetric.sse(tau) - full.sse(tau) > penalty else symmetric
    for step, reach in ((2.0, 6), (1.0, 2), (0.25, 3)):  # +-12, then +-2 samples, then quarter samples
        candidates = (tau + dt * step * j for j in range(-reach, reach + 1))
        tau = min((c for c in candidates if c > earliest), key=physics.sse)
    angle0, rate0 = physics.state_at(tau)
    return ReleaseInstant(tau, physics.instant_se(tau, max(2 * dt, CURVATURE_STEP_S)), angle0, rate0)


#: Knots (s before the instant) of the hold's cubic spline when the hand sways: pieces of 0.15 s follow a
#: sway up to about 3 Hz. The piece next to the instant is kept at 0.2 s: a shorter free cubic there bends
#: into the first tens of ms of the free decay and moves the instant late (0.12 s put one still-hold
#: release 70 ms late); bench/bench_release_sway.py.
SWAY_KNOTS_S = (0.2, 0.35, 0.5)


class ReleaseInstantFit:
    """Held motion before tau, the decay equation after it, jointly on angle and rate.

    After release x'' = -(k0 + c1 y + c2 y^2 + c3 y^3 + b1 x' + b2 |x'|x' + b3 x'^3), y = x - rest.
    Integrating once (rate rows) and twice (angle rows) from tau with the *measured* signals
    inside the integrals makes the model linear in k0 ... b3 (c2 only when ``asymmetric``).
    Every term is such an integral, b1's too (of the measured rate, not the angle's change since
    tau): the angle sample read at tau would shift all rate rows by b1 times its noise, which
    trades one for one against the instant (a heavily damped pitch, b1 ~ 2, lost a sample to it
    at 400 Hz); b1 times the gyro bias is a constant acceleration, taken up by k0. Before tau a
    cubic in time (the hand's slow sway; with ``knots_s``, a cubic spline knotted that long before tau)
    with a free gyro bias; the state at tau is shared, so
    the decay must start where the hand left the model. Rows are weighted by each channel's
    noise, estimated from sample-to-sample differences during the hold. Parameter 0 is the
    angle at tau, 2 its rate.
    """

    def __init__(
        self,
        t: np.ndarray,
        angle: np.ndarray,
        rate: np.ndarray,
        hold: int,
        rest_rad: float,
        asymmetric: bool,
        knots_s: tuple[float, ...] = (),
    ) -> None:
        self.t = t
        self.knots_s = knots_s
        held = slice(0, max(hold, 3))
        self.w_angle = 1.0 / max(float(np.std(np.diff(angle[held]))) / math.sqrt(2), 1e-6)
        self.w_rate = 1.0 / max(float(np.std(np.diff(rate[held]))) / math.sqrt(2), 1e-5)
        self.y = np.concatenate((angle * self.w_angle, rate * self.w_rate))
        from_rest = angle - rest_rad
        # the canonical polynomial terms c1, c2 (if asymmetric), c3, b1, b2, b3
        restoring = [from_rest, from_rest**2, from_rest**3] if asymmetric else [from_rest, from_rest**3]
        integrands = np.array([*restoring, rate, np.abs(rate) * rate, rate**3])
        # running integrals from the window's start, one row per term (once, and twice)
        self.once = self._cumulative(integrands)
        self.twice = self._cumulative(self.once)

    def with_knots(self, knots_s: tuple[float, ...]) -> ReleaseInstantFit:
        """The same fit with the hold's spline knotted at ``knots_s`` (s before tau; the integrals shared)."""
        knotted = copy.copy(self)
        knotted.knots_s = knots_s
        return knotted

    def _cumulative(self, f: np.ndarray) -> np.ndarray:
        steps = 0.5 * (f[:, 1:] + f[:, :-1]) * np.diff(self.t)
        return np.concatenate((np.zeros((f.shape[0], 1)), np.cumsum(steps, axis=1)), axis=1)

    def _design(self, tau: float) -> np.ndarray:
        """The weighted design matrix at tau: angle rows over rate rows, one column per parameter.

        Built in place (one candidate instant is one call, and a release scans about seventy): the
        running integrals are read at tau by one linear interpolation shared by every term.
        """
        t, n, terms = self.t, self.t.size, self.once.shape[0]
        u = t - tau
        first_after = int(np.searchsorted(t, tau, side="left"))  # rows from here on are after tau
        right = min(max(int(np.searchsorted(t, tau, side="right")), 1), n - 1)
        frac = (tau - t[right - 1]) / (t[right] - t[right - 1])
        once_at = self.once[:, right - 1] + frac * (self.once[:, right] - self.once[:, right - 1])
        twice_at = self.twice[:, right - 1] + frac * (self.twice[:, right] - self.twice[:, right - 1])
        k0 = 5 + len(self.knots_s)
        design = np.zeros((2 * n, k0 + 1 + terms))
        angle, rate = design[:n], design[n:]
        before, after = u[:first_after], u[first_after:]
        angle[:, 0], angle[:, 2], rate[:, 1], rate[:, 2] = 1.0, u, 1.0, 1.0
        angle[:first_after, 3], angle[:first_after, 4] = before**2 / 2, before**3 / 3
        rate[:first_after, 3], rate[:first_after, 4] = before, before**2
        for column, knot in enumerate(self.knots_s, start=5):  # the hold's cubic spline, back from tau
            older = np.maximum(-knot - before, 0.0)
            angle[:first_after, column], rate[:first_after, column] = older**3 / 3, -(older**2)
        angle[first_after:, k0], rate[first_after:, k0] = after**2 / 2, after
        angle[first_after:, k0 + 1 :] = (
            once_at[:, None] * after + twice_at[:, None] - self.twice[:, first_after:]
        ).T
        rate[first_after:, k0 + 1 :] = (once_at[:, None] - self.once[:, first_after:]).T
        angle *= self.w_angle
        rate *= self.w_rate
        return design

    def _solve(self, tau: float) -> tuple[np.ndarray, float]:
        """Coefficients and residual sum of squares.

        Normal equations on unit-norm columns: a dozen columns solve in microseconds, where a
        LAPACK QR or SVD per candidate instant costs milliseconds (and far more when OpenBLAS
        threads fight over a busy machine). The residual is formed directly, not from the
        normal equations, so the sums of squares compared between instants stay exact.
        """
        design = self._design(tau)
        gram = design.T @ design  # scaled to unit-norm columns here, not the design: one pass less over it
        norms = np.sqrt(np.diag(gram))
        norms[norms == 0] = 1.0
        scaled = np.linalg.lstsq(gram / np.outer(norms, norms), (design.T @ self.y) / norms, rcond=None)[0]
        coef = scaled / norms  # robust if singular
        residual = self.y - design @ coef
        return coef, float(residual @ residual)

    def sse(self, tau: float) -> float:
        return self._solve(tau)[1]

    def instant_se(self, tau: float, step: float) -> float:
        """Standard error (s) of the fitted instant, from the curvature of the profile sum of squares.

        Near its minimum SSE(tau) ~ SSE_min + (tau - tau_hat)^2 * SSE''/2, so se = sqrt(2 s^2 / SSE'')
        with s^2 the residual variance. The curvature is read over +-``step`` (the sum of squares is
        piecewise in the sample a candidate falls in). A flat or wrongly bent curve (no information)
        answers ``step`` rather than a falsely small error; a quarter of the step, read as uniform, is the
        floor (1.4 ms with the 20 ms step). Measured against the truth it is optimistic: from a swaying
        hold the instants spread 2-2.6 ms where the curvature alone said 1.1-1.3 ms, and the floor is what
        the interval (``COVERAGE_FACTOR``) needs to cover them (bench/bench_release_sway.py).
        """
        centre = self.sse(tau)
        curvature = (self.sse(tau - step) + self.sse(tau + step) - 2.0 * centre) / step**2
        if not curvature > 0:
            return step
        variance = centre / max(self.y.size - self._design(tau).shape[1], 1)
        return float(max(math.sqrt(2.0 * variance / curvature), 0.25 * step / math.sqrt(12.0)))

    def state_at(self, tau: float) -> tuple[float, float]:
        """Fitted angle and angle rate at tau: the initial state of the free decay."""
        coef, _ = self._solve(tau)
        return float(coef[0]), float(coef[2])
