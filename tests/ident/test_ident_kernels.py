"""The sensitivity kernel against the reference integrator and against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tankdaq.ident.compiled import simulate, simulate_with_sensitivities, substeps, term_codes
from tankdaq.physics.decay import TERMS, simulate_decay
from tankdaq.physics.terms import TERM_TABLE

T = np.arange(800) * 0.01
EPS = 0.02


def _run(terms, theta, x0=0.25, v0=0.1, u=None, n_sub=1):
    u = np.zeros_like(T) if u is None else u
    theta, codes, no_input_params = np.asarray(theta, float), term_codes(terms), np.zeros((T.size, 0))
    return simulate_with_sensitivities(T, x0, v0, theta, codes, u, no_input_params, EPS, n_sub)


def test_every_canonical_term_matches_the_reference_integrator():
    coefficients = {
        "b1": 0.3,
        "b2": 0.4,
        "b3": 0.5,
        "c1": 10.0,
        "c2": 0.8,
        "c3": 40.0,
        "s1": 4.0,
        "s2": 0.5,
        "s3": 9,
    }
    x, v, *_, ok = _run(TERMS, [coefficients[k] for k in TERMS])
    ref_x, ref_v = simulate_decay(coefficients, T, 0.25, 0.1)
    assert ok
    assert np.max(np.abs(x - ref_x)) < 1e-6
    assert np.max(np.abs(v - ref_v)) < 1e-5


@pytest.mark.parametrize("terms", [TERMS, ("b1", "c1", "fc", "ku")])
def test_sensitivities_equal_central_differences(terms):
    theta = np.array([{"fc": 0.05, "ku": 2.0}.get(k, 0.3 if k.startswith("b") else 9.0) for k in terms])
    u = 0.05 * np.sin(3.0 * T)
    _x, _v, sx, sv, _ = _run(terms, theta, u=u)
    params = np.concatenate([theta, [0.25, 0.1]])
    for p in range(params.size):
        step = 1e-6 * max(1.0, abs(params[p]))
        up, down = params.copy(), params.copy()
        up[p] += step
        down[p] -= step
        xu, vu, *_ = _run(terms, up[:-2], up[-2], up[-1], u=u)
        xd, vd, *_ = _run(terms, down[:-2], down[-2], down[-1], u=u)
        scale = max(np.max(np.abs(sx[:, p])), 1e-12)
        assert np.max(np.abs((xu - xd) / (2 * step) - sx[:, p])) < 1e-5 * scale
        assert np.max(np.abs((vu - vd) / (2 * step) - sv[:, p])) < 1e-5 * max(np.max(np.abs(sv[:, p])), 1e-12)


def test_friction_and_exogenous_terms_match_an_independent_integration():
    fc, k, b1, c1 = 0.05, 2.0, 0.2, 9.0

    def u_of(t):
        return 0.05 * np.sin(3.0 * t)

    def rhs(t, y):
        return [y[1], -(b1 * y[1] + c1 * y[0] + fc * np.tanh(y[1] / EPS) + k * u_of(t))]

    ref = solve_ivp(rhs, (T[0], T[-1]), [0.25, 0.1], t_eval=T, rtol=1e-10, atol=1e-12, method="DOP853")
    # u is linear between samples inside the kernel: sub-step so that the interpolation error is small
    x, _ = simulate(
        T, 0.25, 0.1, np.array([b1, c1, fc, k]), term_codes(("b1", "c1", "fc", "ku")), u_of(T), EPS, 4
    )
    assert np.max(np.abs(x - ref.y[0])) < 2e-5


def test_divergence_is_reported_not_raised():
    _, _, _, _, ok = _run(("b1", "c1"), [-50.0, 1.0])
    assert not ok


def test_substeps_grow_with_stiffness_and_the_term_table_codes_are_unique():
    assert substeps(0.01, np.array([14.0]), ("c1",), 0.1) == 1
    assert substeps(0.1, np.array([400.0]), ("c1",), 0.1) > 5
    codes = [spec.code for spec in TERM_TABLE.values()]
    assert len(set(codes)) == len(codes)
