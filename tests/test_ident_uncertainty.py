"""Uncertainty beyond the Jacobian: block bootstrap, repeat runs, whiteness checks."""

from __future__ import annotations

import numpy as np
import pytest

from tankdaq.ident.output_error import OutputError
from tankdaq.ident.uncertainty import (
    hac_covariance,
    moving_block_bootstrap,
    repeat_spread,
    residual_whiteness,
)
from test_ident_helpers import synthetic_run, truth_for

TERMS = ("b1", "b2", "c1", "c3")


def test_block_bootstrap_agrees_with_the_jacobian_under_white_noise():
    truth = truth_for(TERMS)
    fit = OutputError(TERMS).fit([synthetic_run(truth, seed=41, duration_s=8.0)])
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
    spread = repeat_spread(lambda: OutputError(TERMS, compute_diagnostics=False), runs)
    for k, value in truth.items():
        lo, hi = spread.ci95[k]
        assert lo < value < hi, k


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
