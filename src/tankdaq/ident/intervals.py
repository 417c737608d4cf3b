"""Intervals that refit: a moving-block bootstrap over the residuals, and the spread over repeat runs.

They sit above the estimators (``OutputErrorFit`` is what a bootstrap resamples), so
that ``ident.uncertainty``, which the estimators use, needs none of them. For the
offline answer: blocks of about a cycle keep the residuals' correlation, and each
replica is refitted warm-started from the fit.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..records import DecayRun
from .output_error import OutputErrorFit
from .uncertainty import hac_covariance


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

    ``estimator`` is a fitted OutputErrorFit; each replica is fitted warm-started
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
    if bootstrap and not isinstance(estimator, OutputErrorFit):  # it resamples the output-error residuals
        raise InputError(f"a bootstrap resamples output-error residuals: use method oe, not {method}")
    if repeats and (bootstrap or n_runs < 3):
        raise InputError("intervals from repeats need at least three runs of one condition, and no bootstrap")


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
