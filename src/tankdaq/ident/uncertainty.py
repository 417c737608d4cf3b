"""Honest uncertainty for decay fits, whose residuals are rarely white.

Three answers, from cheap to thorough: (a) a HAC (Newey-West sandwich)
covariance from the exact Jacobian, used live; (b) a moving-block bootstrap
over the residuals with blocks of about a cycle, refits warm-started, for the
offline answer; (c) the spread over repeat runs. Plus the plain-language
warnings people need to read a fit: terms not distinguishable from zero,
coefficients that trade off, residuals far from white (reference §5).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..records import DecayRun
from .compiled import hac_meat

#: |correlation| above which two coefficients are reported as trading off.
CORRELATION_WARN = 0.95
#: Lag-1 autocorrelation of the residuals above which they are called far from white.
ACF1_WARN = 0.5


def classic_covariance(jac_w: np.ndarray, res_w: np.ndarray, n_free: int) -> np.ndarray:
    """(J'J)^-1 s^2 for residuals already divided by their noise levels, s^2 = RSS / (n - k).

    The noise levels need only be right relative to each other: their common
    scale is estimated from the residual (about 1 when they were re-estimated).
    """
    scale = float(res_w @ res_w) / max(res_w.size - n_free, 1)
    return np.linalg.pinv(jac_w.T @ jac_w) * scale


def bic(residuals: Sequence[np.ndarray], n_params: int, sigmas: Sequence[float] | None = None) -> float:
    """Bayesian information criterion -2 ln L + k ln n of Gaussian residual blocks (run and output).

    The likelihood is the one the fit maximised: with ``sigmas`` (fixed noise
    levels as weights) the blocks' variances are those levels times one unknown
    common scale; without, every block has its own unknown variance. Either way
    the unknown variances are profiled out, so fits of the same data compare
    whatever their number of parameters.
    """
    sizes = np.array([r.size for r in residuals], dtype=float)
    n = float(sizes.sum())
    squares = np.array([float(r @ r) for r in residuals])
    if sigmas is None:
        variances = np.maximum(squares / sizes, 1e-300)
        log_det = float(sizes @ np.log(variances))
    else:
        sig2 = np.square(np.asarray(sigmas, dtype=float))
        scale = max(float(np.sum(squares / sig2)) / n, 1e-300)
        log_det = float(sizes @ np.log(sig2)) + n * math.log(scale)
    return log_det + n * (math.log(2 * math.pi) + 1) + n_params * math.log(n)


ScoreBlocks = Sequence[tuple[list[np.ndarray], list[np.ndarray]]]


def hac_covariance(blocks: ScoreBlocks, bandwidth: int, bias_correction: bool = True) -> np.ndarray:
    """Newey-West sandwich A^-1 S A^-1 with Bartlett weights up to ``bandwidth`` lags, bias-corrected.

    ``blocks`` holds per run the weighted Jacobian (n, p) and residuals (n,) of
    each output; runs are independent and lags stay inside a run. The scores
    g_t (Jacobian rows times residuals, summed over the outputs of one instant)
    are smoothed with the triangular kernel instead of looping over lags.

    Fitted residuals are orthogonal to the Jacobian, so the plain estimate is
    biased low, badly so for a decay whose information sits in its first cycles
    (about -30 % in variance with a one-period bandwidth). The bias under white
    noise is known exactly, E[S] = A - sum_t M_t A^-1 K_t with M_t the
    information of instant t and K_t its triangular smooth, and is added back:
    white residuals then give the classic covariance on average, and residuals
    correlated over a cycle widen the intervals as they should.
    """
    stacked = [
        (np.ascontiguousarray(np.stack(jacs)), np.ascontiguousarray(np.stack(res))) for jacs, res in blocks
    ]
    bread = np.linalg.pinv(sum(np.einsum("otp,otq->pq", jac, jac) for jac, _ in stacked))
    meat = np.zeros_like(bread)
    for jac, res in stacked:
        meat += hac_meat(jac, res, bread, bandwidth, bias_correction)
    meat = 0.5 * (meat + meat.T)
    return bread @ meat @ bread


def correlation_from_covariance(cov: np.ndarray) -> np.ndarray:
    std = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    return np.clip(cov / np.outer(std, std), -1.0, 1.0)


def autocorrelation(residual: np.ndarray, lags: int) -> np.ndarray:
    """Sample autocorrelation of a residual about its mean at lags 1..``lags`` (zeros when it is flat)."""
    r = np.asarray(residual, dtype=float) - np.mean(residual)
    denom = float(r @ r)
    if denom <= 0:
        return np.zeros(lags)
    return np.array([float(r[k:] @ r[:-k]) / denom for k in range(1, lags + 1)])


def ljung_box(residuals: Sequence[np.ndarray], lags: int = 20) -> float:
    """Ljung-Box p of 'no autocorrelation up to ``lags``', Q summed over independent series (runs).

    A short series is tested up to a fifth of its length; chi-square with the
    lags summed over series as degrees of freedom.
    """
    q_total = 0.0
    dof = 0
    for e in residuals:
        n = e.size
        h = min(lags, n // 5)
        if h < 1:
            continue
        acf = autocorrelation(e, h)
        q_total += n * (n + 2) * float(np.sum(acf**2 / (n - np.arange(1, h + 1))))
        dof += h
    return chi_square_survival(max(dof, 1), q_total)


def chi_square_survival(dof: int, q: float) -> float:
    """P(chi-square with ``dof`` degrees of freedom > q), the closed form for whole ``dof``.

    A finite series of Poisson terms (plus erfc for odd ``dof``), summed in logarithms so that
    neither a large ``q`` nor many degrees of freedom overflow: what every live fit's Ljung-Box
    test needs, without scipy.special's 0.1 s import.
    """
    if q <= 0.0:
        return 1.0
    half = 0.5 * q
    odd = dof % 2 == 1
    total = math.erfc(math.sqrt(half)) if odd else 0.0
    shift = 0.5 if odd else 0.0  # the Poisson terms' exponents: i + 1/2 for odd dof, i for even
    log_half = math.log(half)
    for i in range(dof // 2):
        exponent = i + shift
        total += math.exp(exponent * log_half - half - math.lgamma(exponent + 1.0))
    return min(total, 1.0)


def residual_whiteness(residual: np.ndarray, lags: int = 20) -> tuple[float, float]:
    """Lag-1 autocorrelation and the Ljung-Box p-value over ``lags`` lags."""
    return float(autocorrelation(residual, 1)[0]), ljung_box([residual], lags)


def coefficient_warnings(
    names: Sequence[str], values: np.ndarray, std: np.ndarray, correlation: np.ndarray
) -> list[str]:
    """Plain-language warnings about terms near zero and terms that trade off."""
    out = [
        f"{name} = {value:.4g} is not distinguishable from zero (|value| < 2 std = {2 * s:.3g}); "
        f"consider a model without it"
        for name, value, s in zip(names, values, std, strict=True)
        if abs(value) < 2.0 * s
    ]
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if abs(correlation[i, j]) > CORRELATION_WARN:
                out.append(
                    f"{names[i]} and {names[j]} are strongly correlated ({correlation[i, j]:+.3f}): "
                    f"the data cannot separate them; report B_eq over the tested amplitudes "
                    f"or add release angles"
                )
    return out


def whiteness_warning(run_name: str, output: str, acf1: float, ljung_box_p: float) -> str | None:
    """A warning when residuals look like model error rather than noise (intervals then need (b) or (c))."""
    if acf1 > ACF1_WARN or ljung_box_p < 1e-3:
        return (
            f"{run_name}: {output} residuals are far from white (lag-1 autocorrelation {acf1:.2f}, "
            f"Ljung-Box p {ljung_box_p:.1e}): model error dominates; trust bootstrap or repeat-run intervals"
        )
    return None


@dataclass
class IntervalSummary:
    """Spread of each coefficient from resampling or repeats: std and 95 % interval."""

    method: str
    std: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    samples: np.ndarray  # (n_samples, n_terms)
    counted: str = "replicas"  # what the samples are: bootstrap replicas, repeat runs

    @property
    def description(self) -> str:
        """How the intervals were found, as the report says it ("repeat runs, 3 runs")."""
        return f"{self.method}, {self.samples.shape[0]} {self.counted}"


def moving_block_bootstrap(
    estimator: Any,
    n_boot: int = 100,
    block_periods: float = 1.0,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> IntervalSummary:
    """Refit on fitted curve + residuals resampled in blocks of about a cycle (keeps their correlation).

    ``estimator`` is a fitted OutputError; each replica is fitted warm-started
    from it. Fitted residuals are orthogonal to the Jacobian, which makes
    resampled blocks of them too quiet in the directions the fit used (the same
    bias as in the HAC estimate, whose Bartlett form the moving-block bootstrap
    mimics): each coefficient's replica spread is therefore scaled by the ratio
    of the bias-corrected to the plain HAC standard error at the block length.
    Intervals are percentile intervals of the scaled replicas.
    """
    rng = np.random.default_rng(seed)
    runs: list[DecayRun] = estimator.runs_
    period = estimator.natural_period_s_
    blocks = [
        max(2, min(run.t.size, round(block_periods * period / float(np.median(np.diff(run.t))))))
        for run in runs
    ]
    samples = []
    for b in range(n_boot):
        replicas = []
        for run, fitted, resid, block in zip(
            runs, estimator.fitted_, estimator.residuals_, blocks, strict=True
        ):
            n = run.t.size
            starts = rng.integers(0, n - block + 1, size=int(np.ceil(n / block)))
            idx = np.concatenate([np.arange(s, s + block) for s in starts])[:n]
            if run.excluded is not None:  # an excluded (clipped) sample's residual is not noise: not drawn
                drawn = idx[run.kept[idx]]
                idx = np.resize(drawn, n) if drawn.size else idx
            angle = fitted["angle"] + resid["angle"][idx]
            rate = None if resid["rate"] is None else fitted["rate"] + resid["rate"][idx]
            replicas.append(
                DecayRun(
                    t=run.t,
                    angle=angle,
                    rate=rate,
                    axis=run.axis,
                    name=run.name,
                    channels=run.channels,
                    excluded=run.excluded,
                )
            )
        clone = estimator.clone(compute_diagnostics=False)
        clone.fit(replicas, start=estimator)
        samples.append([clone.coefficients_[k] for k in estimator.terms_])
        if progress is not None:
            progress(b + 1)
    n_theta = len(estimator.terms_)
    corrected = np.diag(hac_covariance(estimator.score_blocks_, blocks[0]))[:n_theta]
    plain = np.diag(hac_covariance(estimator.score_blocks_, blocks[0], bias_correction=False))[:n_theta]
    centre = np.array([estimator.coefficients_[k] for k in estimator.terms_])
    scale = np.sqrt(corrected / np.clip(plain, 1e-300, None))
    scaled = centre + (np.array(samples) - centre) * scale
    return _summary("moving-block bootstrap", estimator.terms_, scaled, percentile=True)


def repeat_spread(make_estimator: Callable[[], Any], runs: Sequence[DecayRun]) -> IntervalSummary:
    """Fit every run alone; the scatter of the repeats gives the standard error of their mean.

    The interval is the mean +- t(0.975, n-1) * std / sqrt(n): the honest answer
    when residuals are model error, provided the runs are true repeats.
    """
    fits = [make_estimator().fit([run]) for run in runs]
    terms = fits[0].terms_
    values = np.array([[f.coefficients_[k] for k in terms] for f in fits])
    return _summary("repeat runs", terms, values, percentile=False, counted="runs")


def check_intervals(estimator: Any, n_runs: int, bootstrap: int, repeats: bool, method: str = "oe") -> None:
    """Refuse the interval requests that cannot work, before any fit (``InputError``, one line)."""
    from ..errors import InputError
    from .output_error import OutputError  # it imports this module

    if bootstrap and not isinstance(estimator, OutputError):  # it resamples the output-error residuals
        raise InputError(f"--bootstrap works with --method oe, not {method}")
    if repeats and (bootstrap or n_runs < 3):
        raise InputError("--repeats needs at least three runs (repeats of one condition) and no --bootstrap")


def fit_with_intervals(
    estimator: Any,
    runs: Sequence[DecayRun],
    bootstrap: int = 0,
    repeats_of: Callable[[], Any] | None = None,
    progress: Callable[[int], None] | None = None,
    method: str = "oe",
) -> tuple[Any, IntervalSummary | None]:
    """Fit ``estimator``, then the intervals asked for beside it: a moving-block bootstrap of
    ``bootstrap`` replicas, or (``repeats_of``, a factory of unfitted estimators) the spread of the
    runs fitted one by one as repeats. The fitted estimator keeps its own ``std_``/``ci95_``; the
    report reads the returned intervals instead (``report.summarize(..., intervals=)``).

    ``progress(done)`` counts the fit as 1 and each replica after it. The combinations that cannot
    work are refused before any fit (``method`` names the estimator in the message).
    """
    check_intervals(estimator, len(runs), bootstrap, repeats_of is not None, method)
    estimator.fit(runs)
    if progress is not None:
        progress(1)
    intervals = None
    if bootstrap:
        on_replica = None if progress is None else (lambda done: progress(1 + done))
        intervals = moving_block_bootstrap(estimator, bootstrap, progress=on_replica)
    elif repeats_of is not None:
        intervals = repeat_spread(repeats_of, runs)
    return estimator, intervals


def _summary(
    method: str, terms: Sequence[str], values: np.ndarray, percentile: bool, counted: str = "replicas"
) -> IntervalSummary:
    std = values.std(axis=0, ddof=1) if values.shape[0] > 1 else np.full(values.shape[1], np.nan)
    if percentile:
        lo, hi = np.percentile(values, [2.5, 97.5], axis=0)
        spread = std
    else:
        n = values.shape[0]
        spread = std / np.sqrt(n)
        mean = values.mean(axis=0)
        from scipy import special  # scipy.special costs 0.1 s to import: only for repeat runs

        half = special.stdtrit(max(n - 1, 1), 0.975) * spread  # Student t quantile
        lo, hi = mean - half, mean + half
    return IntervalSummary(
        method=method,
        std=dict(zip(terms, spread.tolist(), strict=True)),
        ci95={k: (float(a), float(b)) for k, a, b in zip(terms, lo, hi, strict=True)},
        samples=values,
        counted=counted,
    )
