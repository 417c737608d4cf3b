"""Uncertainty beyond the Jacobian: block bootstrap, repeat runs, whiteness checks."""

from __future__ import annotations

import numpy as np
import pytest

from support.ident_helpers import synthetic_run, truth_for
from tankdaq.errors import InputError
from tankdaq.ident.equation_error import EquationErrorFit
from tankdaq.ident.intervals import fit_with_intervals, moving_block_bootstrap, repeat_spread
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.ident.report import summarize
from tankdaq.ident.uncertainty import bic, hac_covariance, ljung_box, residual_whiteness

TERMS = ("b1", "b2", "c1", "c3")


def test_block_bootstrap_agrees_with_the_jacobian_under_white_noise():
    truth = truth_for(TERMS)
    fit = OutputErrorFit(TERMS).fit([synthetic_run(truth, seed=41, duration_s=8.0)])
    done = []
    spread = moving_block_bootstrap(fit, n_boot=40, seed=1, progress=done.append)
    assert done[-1] == 40 and spread.samples.shape == (40, len(TERMS))
    for k in TERMS:
        # 40 replicas estimate a std to about +-11 %: agreement within a factor 1.5 either way
        assert 1 / 1.5 < spread.std[k] / fit.std_[k] < 1.5, k
        lo, hi = spread.ci95[k]
        assert lo < fit.coefficients_[k] < hi


def test_repeat_runs_give_a_t_interval_around_the_truth():
    truth = truth_for(TERMS)
    runs = [synthetic_run(truth, seed=50 + i, duration_s=8.0) for i in range(5)]
    spread = repeat_spread(lambda: OutputErrorFit(TERMS, compute_diagnostics=False), runs)
    for k, value in truth.items():
        lo, hi = spread.ci95[k]
        assert lo < value < hi, k


def test_intervals_are_returned_beside_the_fit_which_keeps_its_own() -> None:
    """Repeat-run intervals come back as data; the fitted estimator's std_/ci95_ stay the fit's, and
    the report reads the intervals it is given."""
    truth = truth_for(TERMS)
    runs = [synthetic_run(truth, seed=60 + i, duration_s=8.0) for i in range(3)]
    steps: list[int] = []
    fitted, intervals = fit_with_intervals(
        OutputErrorFit(TERMS), runs, repeats_of=lambda: OutputErrorFit(TERMS, compute_diagnostics=False),
        progress=steps.append,
    )  # fmt: skip
    alone = OutputErrorFit(TERMS).fit(runs)
    assert steps == [1] and intervals is not None and intervals.description == "repeat runs, 3 runs"
    assert fitted.std_ == pytest.approx(alone.std_) and fitted.ci95_ == alone.ci95_
    assert intervals.std != pytest.approx(fitted.std_)  # the spread of three repeats is another number
    summary = summarize(fitted, runs, intervals=intervals)
    assert summary.intervals == "repeat runs, 3 runs"
    for k in TERMS:
        assert summary.coefficients[k].std == intervals.std[k]
        assert summary.to_dict()["coefficients"][k]["ci95"] == list(intervals.ci95[k])


@pytest.mark.parametrize(
    ("method", "bootstrap", "n_runs", "mentions"),
    [
        ("ee", 10, 3, "use method oe, not ee"),
        ("oe", 10, 3, "repeats need at least three runs .* and no bootstrap"),
        ("oe", 0, 2, "repeats need at least three runs"),
    ],
)
def test_intervals_that_cannot_work_are_refused_before_any_fit(
    method: str, bootstrap: int, n_runs: int, mentions: str
) -> None:
    estimator = EquationErrorFit(TERMS) if method == "ee" else OutputErrorFit(TERMS)
    runs = [synthetic_run(truth_for(TERMS), seed=70 + i, duration_s=8.0) for i in range(n_runs)]
    repeats_of = None if method == "ee" else (lambda: OutputErrorFit(TERMS))
    with pytest.raises(InputError, match=mentions):
        fit_with_intervals(estimator, runs, bootstrap, repeats_of, method=method)
    assert not hasattr(estimator, "coefficients_")  # nothing was fitted


def test_hac_widens_intervals_when_residuals_are_correlated():
    """Residuals that are a slow random walk: the HAC variance must exceed the white-noise one."""
    rng = np.random.default_rng(3)
    n = 2000
    jac = np.column_stack([np.sin(np.arange(n) / 30.0), np.ones(n)])
    white = rng.normal(size=n)
    correlated = np.convolve(rng.normal(size=n + 99), np.ones(100) / 10.0, mode="valid")
    correlated -= jac @ np.linalg.lstsq(jac, correlated, rcond=None)[0]
    white -= jac @ np.linalg.lstsq(jac, white, rcond=None)[0]
    cov_white = hac_covariance([([jac], [white])], 150)
    cov_corr = hac_covariance([([jac], [correlated / correlated.std()])], 150)
    assert cov_white[0, 0] == pytest.approx(np.linalg.inv(jac.T @ jac)[0, 0] * white.var(), rel=0.35)
    assert cov_corr[0, 0] > 5 * cov_white[0, 0]


def test_whiteness_statistics():
    rng = np.random.default_rng(4)
    acf1, p = residual_whiteness(rng.normal(size=3000))
    assert abs(acf1) < 0.06 and p > 1e-3
    acf1, p = residual_whiteness(np.sin(np.arange(3000) / 20.0))
    assert acf1 > 0.9 and p < 1e-6


def test_ljung_box_accepts_white_noise_and_rejects_coloured() -> None:
    rng = np.random.default_rng(2)
    white = [rng.normal(size=1500) for _ in range(3)]
    p_values = [ljung_box([rng.normal(size=1500) for _ in range(3)]) for _ in range(200)]
    # under H0 the p-value is uniform: about 5 % below 0.05
    assert 0.01 <= np.mean(np.array(p_values) < 0.05) <= 0.11
    assert ljung_box(white) > 1e-3
    coloured = [np.convolve(w, np.ones(5) / 5, mode="same") for w in white]
    assert ljung_box(coloured) < 1e-12


def test_bic_is_minus_twice_the_gaussian_log_likelihood_plus_the_parameter_penalty() -> None:
    rng = np.random.default_rng(5)
    blocks = [rng.normal(0, 2.0, 400), rng.normal(0, 0.5, 600)]
    n = 1000
    # each block its own variance, profiled out
    expected = sum(b.size * (np.log(2 * np.pi * np.mean(b**2)) + 1) for b in blocks) + 3 * np.log(n)
    assert bic(blocks, 3) == pytest.approx(expected)
    # known relative noise levels, one common scale profiled out
    sigmas = [2.0, 0.5]
    scale = sum(float(np.sum((b / s) ** 2)) for b, s in zip(blocks, sigmas, strict=True)) / n
    log_det = sum(b.size * np.log(s**2 * scale) for b, s in zip(blocks, sigmas, strict=True))
    assert bic(blocks, 3, sigmas) == pytest.approx(log_det + n * (np.log(2 * np.pi) + 1) + 3 * np.log(n))
    # the right levels given: both agree closely
    assert bic(blocks, 3, sigmas) == pytest.approx(bic(blocks, 3), abs=5.0)


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 19, 20, 21, 101, 720])
def test_the_closed_form_chi_square_survival_is_scipys(dof: int) -> None:
    """Ljung-Box's p without scipy.special: the same to 1e-11 from the far left tail to the far right."""
    from scipy.special import chdtrc

    from tankdaq.ident.uncertainty import chi_square_survival

    for q in [0.0, 1e-9, 0.01, 0.5, 1.0, dof / 2, dof, dof + 3 * (2 * dof) ** 0.5, 3 * dof, 1e3, 5e4]:
        want = float(chdtrc(dof, q))
        got = chi_square_survival(dof, q)
        assert got == pytest.approx(want, rel=1e-11, abs=1e-300), (dof, q)
