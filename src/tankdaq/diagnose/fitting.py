"""Output-error refits of one model variant, jointly over runs, for the discrepancy workflow.

The workflow refits the whole decay by simulation error for every candidate
effect (a few dozen refits per diagnosis), so each refit has to cost
milliseconds: the compiled fixed-step RK4 of ``ident.kernels`` on the sample
grid (the same equation and integrator as the estimators), forward-difference
Jacobians that re-simulate only the run a parameter touches, and
Levenberg-Marquardt. Besides the canonical terms b1..s3 a variant may hold
Coulomb friction ``fc*tanh(x'/eps)``, coupling ``k*u(t)`` to measured channels,
a forcing by an unmeasured motion ringing down at its own frequency, and
observation parameters (per-run angle offset, angle gain error, angle lag,
gyro bias): ``y_angle = (1 + g) x(t - tau) + offset``, ``y_rate = x' + bias``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import butter, sosfiltfilt

from ..errors import BadIdentificationInput, IdentificationError
from ..ident.kernels import simulate, term_codes
from ..physics.decay import TERMS
from ..records import DecayRun
from .residuals import ljung_box_p, noise_level

#: Smoothing rate of the Coulomb term fc*tanh(x'/eps): a dry friction that switches within 0.005 rad/s.
COULOMB_EPS_RAD_S = 0.005
_DIVERGED = 1e3  # value a diverging simulation is clamped to, so least squares backs off instead of crashing
_CANONICAL_CODES = term_codes(TERMS)
_COULOMB_CODE = term_codes(("fc",))
_FORCING_CODE = term_codes(("ku",))


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
    def global_names(self) -> list[str]:
        """Parameters shared by all runs, in vector order."""
        names = list(self.terms)
        if self.coulomb:
            names.append("fc")
        names += [f"k_{ch}" for ch in self.coupling]
        if self.gain:
            names.append("angle_gain_error")
        if self.lag:
            names.append("angle_lag_s")
        if self.gyro_bias:
            names.append("gyro_bias_rad_s")
        if self.ring:
            names += ["ring_omega_rad_s", "ring_decay_1_s"]
        return names

    @property
    def run_names(self) -> list[str]:
        """Parameters of each run: initial state, optionally the angle offset and the ringing's amplitude."""
        return (
            ["angle0", "rate0"]
            + (["angle_offset_rad"] if self.offset else [])
            + (["ring_cos", "ring_sin"] if self.ring else [])
        )

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


def simulate_rk4(
    t: np.ndarray, forcing: np.ndarray, coef: np.ndarray, fc: float, x0: float, v0: float
) -> tuple[np.ndarray, np.ndarray]:
    """Angle and rate on the sample grid, integrated by ``ident.kernels`` (one equation, one RK4).

    ``coef`` holds b1..s3 in ``TERMS`` order. The forcing sits on the left-hand
    side like ident's ``ku*u(t)``, so it goes in as u with a unit ku. Terms with
    a zero coefficient are left out: sin and tanh cost more than the rest together.
    A solution leaving the sane range is clamped to ``_DIVERGED`` from there on,
    so least squares backs off instead of chasing inf.
    """
    used = np.flatnonzero(coef)
    codes = [_CANONICAL_CODES[used]]
    theta = [coef[used]]
    if fc != 0.0:
        codes.append(_COULOMB_CODE)
        theta.append(np.array([fc]))
    if np.any(forcing):
        codes.append(_FORCING_CODE)
        theta.append(np.ones(1))
    x, v = simulate(
        t, float(x0), float(v0), np.concatenate(theta), np.concatenate(codes), forcing, COULOMB_EPS_RAD_S, 1
    )
    outside = ~((np.abs(x) < _DIVERGED) & (np.abs(v) < _DIVERGED))  # NaN counts as outside
    if outside.any():
        first = int(np.argmax(outside))
        x[first:] = _DIVERGED
        v[first:] = _DIVERGED
    return x, v


def _end_acceleration(t: np.ndarray, v: np.ndarray, end: int) -> float:
    """Second-order one-sided derivative of the rate at the first (end=0) or last (end=-1) sample."""
    if end == 0:
        return float((-3 * v[0] + 4 * v[1] - v[2]) / (t[2] - t[0]))
    return float((3 * v[-1] - 4 * v[-2] + v[-3]) / (t[-1] - t[-3]))


def lagged(t: np.ndarray, x: np.ndarray, v: np.ndarray, lag_s: float) -> np.ndarray:
    """x(t - lag) from the grid values: cubic Hermite inside, second-order Taylor beyond the ends."""
    if lag_s == 0.0:
        return x
    s = t - lag_s
    i = np.clip(np.searchsorted(t, s) - 1, 0, t.size - 2)
    h = t[i + 1] - t[i]
    u = (s - t[i]) / h
    h00 = (1 + 2 * u) * (1 - u) ** 2
    h10 = u * (1 - u) ** 2
    h01 = u * u * (3 - 2 * u)
    h11 = u * u * (u - 1)
    out = h00 * x[i] + h10 * h * v[i] + h01 * x[i + 1] + h11 * h * v[i + 1]
    for end, outside in ((0, s < t[0]), (-1, s > t[-1])):
        if np.any(outside):
            d = s[outside] - t[end]
            out[outside] = x[end] + d * v[end] + 0.5 * d * d * _end_acceleration(t, v, end)
    return out


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
    """One converged output-error fit of a ModelSpec."""

    spec: ModelSpec
    coefficients: dict[str, float]
    std: dict[str, float]
    run_params: list[dict[str, float]]  # per run: angle0, rate0 and what else the spec fits per run
    runs: list[RunPrediction]
    rss: float  # weighted (angle / sigma_angle, rate / sigma_rate)
    n: int
    k: int
    params: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    @property
    def initial_states(self) -> list[tuple[float, float]]:
        return [(p["angle0"], p["rate0"]) for p in self.run_params]

    @property
    def offsets(self) -> list[float]:
        """Per-run angle offsets, empty when the model has none."""
        return [p["angle_offset_rad"] for p in self.run_params] if self.spec.offset else []

    @property
    def bic(self) -> float:
        return float(self.n * np.log(self.rss / self.n) + self.k * np.log(self.n))

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
        num = sum(float(np.sum(r.residual_angle**2)) for r in self.runs)
        den = sum(
            float(np.sum((r.angle + r.residual_angle - np.mean(r.angle + r.residual_angle)) ** 2))
            for r in self.runs
        )
        return float(np.sqrt(num / den))

    @property
    def nrmse_rate(self) -> float | None:
        runs = [r for r in self.runs if r.residual_rate is not None]
        if not runs:
            return None
        num = sum(float(np.sum(r.residual_rate**2)) for r in runs)
        den = sum(
            float(np.sum((r.rate + r.residual_rate - np.mean(r.rate + r.residual_rate)) ** 2)) for r in runs
        )
        return float(np.sqrt(num / den))

    @property
    def fit_percent(self) -> float:
        return 100.0 * (1.0 - self.nrmse_angle)

    @property
    def ljung_box_p(self) -> float:
        return ljung_box_p([r.residual_angle for r in self.runs], model_df=0)


#: Measured channels used as a forcing are low-passed here: ship motions live well below it.
CHANNEL_CUTOFF_HZ = 5.0


def forcing_channel(values: np.ndarray, rate_hz: float) -> np.ndarray:
    """A measured channel made fit to drive the equation of motion.

    About its mean: a static part (gravity in acc_z, the tracker's zero) is an
    offset, not a coupling. Low-passed (zero phase): its sensor noise would
    otherwise enter as a random forcing, a process noise the model cannot have.
    """
    centred = np.asarray(values, dtype=float) - np.mean(values)
    cutoff = min(CHANNEL_CUTOFF_HZ, 0.4 * rate_hz)
    if centred.size < 30:
        return centred
    sos = butter(4, cutoff, fs=rate_hz, output="sos")
    return sosfiltfilt(sos, centred)


@dataclass
class _RunData:
    run: DecayRun
    sigma_angle: float
    sigma_rate: float
    channels: dict[str, np.ndarray]


def _prepare(runs: Sequence[DecayRun], spec: ModelSpec) -> list[_RunData]:
    if not runs:
        raise BadIdentificationInput("no runs to fit")
    prepared = []
    for run in runs:
        if run.t.size < 20:
            raise BadIdentificationInput(f"{run.name}: only {run.t.size} samples; a decay needs at least 20")
        missing = [ch for ch in spec.coupling if ch not in run.channels]
        if missing:
            raise BadIdentificationInput(f"{run.name}: no measured channel {missing} for the coupling term")
        if run.rate is None and (spec.lag or spec.gyro_bias or spec.gain):
            raise BadIdentificationInput(f"{run.name}: lag, gain and gyro bias need a measured rate")
        sigma_angle = max(noise_level(run.angle), 1e-9)
        sigma_rate = max(noise_level(run.rate), 1e-9) if run.rate is not None else 1.0
        channels = {ch: forcing_channel(run.channels[ch], run.sample_rate) for ch in spec.coupling}
        prepared.append(_RunData(run, sigma_angle, sigma_rate, channels))
    return prepared


class _Problem:
    """Parameter vector <-> model, residual vector, Jacobian by forward differences."""

    def __init__(self, data: list[_RunData], spec: ModelSpec):
        self.data = data
        self.spec = spec
        self.gnames = spec.global_names
        self.nrun = len(spec.run_names)
        self.ng = len(self.gnames)
        self.sizes = [d.run.t.size * (1 if d.run.rate is None else 2) for d in data]
        self.bounds = np.cumsum([0, *self.sizes])
        self._last: tuple[np.ndarray | None, np.ndarray] = (None, np.zeros(0))  # (p, residual) last evaluated

    def unpack(self, p: np.ndarray) -> tuple[dict[str, float], np.ndarray]:
        return dict(zip(self.gnames, p[: self.ng], strict=True)), p[self.ng :].reshape(
            len(self.data), self.nrun
        )

    def predict(self, d: _RunData, g: dict[str, float], rp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        coef = np.array([g.get(name, 0.0) for name in TERMS])
        forcing = np.zeros(d.run.t.size)
        for ch, u in d.channels.items():
            forcing += g[f"k_{ch}"] * u
        own = dict(zip(self.spec.run_names, rp, strict=True))
        if self.spec.ring:
            since = d.run.t - d.run.t[0]
            phase = g["ring_omega_rad_s"] * since
            envelope = np.exp(-g["ring_decay_1_s"] * since)
            forcing += envelope * (own["ring_cos"] * np.cos(phase) + own["ring_sin"] * np.sin(phase))
        x, v = simulate_rk4(d.run.t, forcing, coef, g.get("fc", 0.0), own["angle0"], own["rate0"])
        angle = (1.0 + g.get("angle_gain_error", 0.0)) * lagged(d.run.t, x, v, g.get("angle_lag_s", 0.0))
        angle = angle + own.get("angle_offset_rad", 0.0)
        return angle, v + g.get("gyro_bias_rad_s", 0.0)

    def run_residual(self, d: _RunData, g: dict[str, float], rp: np.ndarray) -> np.ndarray:
        angle, rate = self.predict(d, g, rp)
        r_angle = (d.run.angle - angle) / d.sigma_angle
        if d.run.rate is None:
            return r_angle
        return np.concatenate([r_angle, (d.run.rate - rate) / d.sigma_rate])

    def residual(self, p: np.ndarray) -> np.ndarray:
        g, rps = self.unpack(p)
        value = np.concatenate([self.run_residual(d, g, rp) for d, rp in zip(self.data, rps, strict=True)])
        self._last = (p.copy(), value)  # LM asks for the Jacobian where it just evaluated the residual
        return value

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        g, rps = self.unpack(p)
        last_p, last_value = self._last
        at_last = last_p is not None and np.array_equal(last_p, p)
        jac = np.zeros((int(self.bounds[-1]), p.size))
        for r, (d, rp) in enumerate(zip(self.data, rps, strict=True)):
            rows = slice(self.bounds[r], self.bounds[r + 1])
            base = last_value[rows] if at_last else self.run_residual(d, g, rp)
            for j, name in enumerate(self.gnames):
                step = 1e-7 * max(abs(g[name]), 1e-2)
                jac[rows, j] = (self.run_residual(d, {**g, name: g[name] + step}, rp) - base) / step
            for j in range(self.nrun):
                step = 1e-7 * max(abs(rp[j]), 1e-2)
                bumped = rp.copy()
                bumped[j] += step
                jac[rows, self.ng + r * self.nrun + j] = (self.run_residual(d, g, bumped) - base) / step
        return jac


def _start_vector(problem: _Problem, start: Fit | None, guess: dict[str, float]) -> np.ndarray:
    """Previous fit's values where it has them, the model-free guess for the rest, zero otherwise."""
    known = dict(guess)
    if start is not None:
        # a swapped spring (c1*x <-> s1*sin x) starts from the stiffness it replaces
        known |= {"s1": start.coefficients.get("c1", 0.0), "c1": start.coefficients.get("s1", 0.0)}
        known |= start.coefficients
    glob = [known.get(name, 0.0) for name in problem.gnames]
    per_run = []
    for i, d in enumerate(problem.data):
        measured = {
            "angle0": float(d.run.angle[0]),
            "rate0": float(d.run.rate[0])
            if d.run.rate is not None
            else float((d.run.angle[1] - d.run.angle[0]) / (d.run.t[1] - d.run.t[0])),
        }
        if start is not None and i < len(start.run_params):
            measured |= start.run_params[i]
        per_run += [measured.get(name, 0.0) for name in problem.spec.run_names]
    return np.array(glob + per_run, dtype=float)


def fit_spec(
    runs: Sequence[DecayRun],
    spec: ModelSpec,
    start: Fit | None = None,
    guess: dict[str, float] | None = None,
    max_nfev: int = 60,
) -> Fit:
    """Fit ``spec`` to all runs jointly by output error (angle, and rate when measured, noise-weighted)."""
    data = _prepare(runs, spec)
    problem = _Problem(data, spec)
    p0 = _start_vector(problem, start, guess or {})
    with np.errstate(over="ignore", invalid="ignore"):
        sol = least_squares(
            problem.residual, p0, jac=problem.jacobian, method="lm", max_nfev=max_nfev * p0.size
        )
    if not np.all(np.isfinite(sol.x)):
        raise IdentificationError(f"the fit of {spec.describe()} diverged")
    rss = float(np.sum(sol.fun**2))
    n = int(sol.fun.size)
    g, rps = problem.unpack(sol.x)
    return Fit(
        spec=spec,
        coefficients={k: float(v) for k, v in g.items()},
        std=_standard_errors(sol.jac, rss, n, problem.gnames),
        run_params=[{k: float(v) for k, v in zip(spec.run_names, rp, strict=True)} for rp in rps],
        runs=_predictions(problem, sol.x),
        rss=rss,
        n=n,
        k=int(sol.x.size),
        params=sol.x,
    )


def _predictions(problem: _Problem, p: np.ndarray) -> list[RunPrediction]:
    g, rps = problem.unpack(p)
    preds = []
    for d, rp in zip(problem.data, rps, strict=True):
        angle, rate = problem.predict(d, g, rp)
        preds.append(
            RunPrediction(
                name=d.run.name,
                t=d.run.t,
                angle=angle,
                rate=rate,
                residual_angle=d.run.angle - angle,
                residual_rate=None if d.run.rate is None else d.run.rate - rate,
            )
        )
    return preds


def predict(fit: Fit, runs: Sequence[DecayRun]) -> list[RunPrediction]:
    """The fitted model simulated over other records of the same runs (e.g. the full ones after a cut)."""
    if len(runs) != len(fit.initial_states):
        raise BadIdentificationInput(f"the fit has {len(fit.initial_states)} runs, {len(runs)} were given")
    return _predictions(_Problem(_prepare(runs, fit.spec), fit.spec), fit.params)


def _standard_errors(jac: np.ndarray, rss: float, n: int, names: list[str]) -> dict[str, float]:
    """White-noise standard errors of the shared parameters (optimistic when residuals are coloured)."""
    dof = max(n - jac.shape[1], 1)
    try:
        cov = np.linalg.pinv(jac.T @ jac) * rss / dof
    except np.linalg.LinAlgError:  # pragma: no cover - SVD failure on a singular Jacobian
        return {name: float("nan") for name in names}
    return {name: float(np.sqrt(max(cov[j, j], 0.0))) for j, name in enumerate(names)}
