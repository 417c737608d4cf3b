"""Output error on known-truth decays: recovery, interval coverage, observation effects, extra terms."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import solve_ivp

from support.ident_helpers import synthetic_run, truth_for
from tankdaq.errors import BadIdentificationInput
from tankdaq.ident.equation_error import EquationErrorFit
from tankdaq.ident.observation_lag import LagOperator
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.decay import simulate_decay
from tankdaq.physics.models import MODEL_ALIASES
from tankdaq.records import DecayRun

#: Each term must lie inside its 99.9 % interval (3.29 std) in these single fixed-seed checks;
#: the 95 % level is checked statistically in the coverage test below.
Z999 = 3.29

UNIQUE_MODELS = sorted({alias.terms for alias in MODEL_ALIASES.values()})


@pytest.mark.parametrize("terms", UNIQUE_MODELS, ids=[",".join(t) for t in UNIQUE_MODELS])
@pytest.mark.slow
def test_every_model_recovers_its_truth(terms):
    truth = truth_for(terms)
    run = synthetic_run(truth, seed=len(terms))
    fit = OutputErrorFit(terms).fit([run])
    for k, value in truth.items():
        assert abs(fit.coefficients_[k] - value) < Z999 * fit.std_[k], (k, fit.coefficients_[k], fit.std_[k])
    assert abs(fit.offsets_[0] - 0.01) < 1e-3
    assert fit.r2_angle_ > 0.999


def test_joint_fit_shares_coefficients_and_keeps_per_run_state():
    truth = truth_for(("b1", "b2", "c1", "c3"))
    runs = [
        synthetic_run(truth, seed=s, angle0=a0, offset=off)
        for s, a0, off in ((1, 0.3, 0.01), (2, -0.15, -0.02))
    ]
    fit = OutputErrorFit(tuple(truth)).fit(runs)
    for k, value in truth.items():
        assert abs(fit.coefficients_[k] - value) < Z999 * fit.std_[k]
    assert fit.offsets_ == pytest.approx([0.01, -0.02], abs=1e-3)
    assert [s[0] for s in fit.initial_states_] == pytest.approx([0.3, -0.15], abs=3e-3)
    assert len(fit.residuals_) == 2


def test_angle_only_runs_are_fitted_too():
    truth = truth_for(("b1", "b2", "c1", "c3"))
    fit = OutputErrorFit(tuple(truth)).fit([synthetic_run(truth, seed=5, with_rate=False)])
    for k, value in truth.items():
        assert abs(fit.coefficients_[k] - value) < Z999 * fit.std_[k]


@pytest.mark.slow
@pytest.mark.parametrize("cov_type", ["hac", "classic"])
def test_95_percent_intervals_cover_the_truth_about_95_percent_of_the_time(cov_type):
    """Over N independent noise draws each term's 95 % interval must contain the truth a number of
    times inside the central 99.8 % of Binomial(N, 0.95): a calibrated interval fails this 1 in 500."""
    truth = truth_for(("b1", "b2", "c1", "c3"))
    n = 150
    hits = dict.fromkeys(truth, 0)
    for seed in range(n):
        fit = OutputErrorFit(tuple(truth), cov_type=cov_type, compute_diagnostics=False).fit(
            [synthetic_run(truth, seed=1000 + seed, duration_s=8.0)]
        )
        for k, value in truth.items():
            lo, hi = fit.ci95_[k]
            hits[k] += lo <= value <= hi
    low, high = stats.binom.ppf([0.001, 0.999], n, 0.95)
    for k, count in hits.items():
        assert low <= count <= high, (k, count, (low, high))


def test_warnings_name_terms_that_are_not_there_and_coupled_terms():
    truth = truth_for(("b1", "c1", "c3"))
    fit = OutputErrorFit(("b1", "b2", "b3", "c1", "c3")).fit([synthetic_run(truth, seed=3)])
    text = " ".join(fit.warnings_)
    assert "b3" in text and "not distinguishable from zero" in text
    assert "strongly correlated" in text


def test_equation_error_gives_usable_starting_values():
    truth = truth_for(("b1", "b2", "c1", "c3"))
    fit = EquationErrorFit(tuple(truth)).fit([synthetic_run(truth, seed=4)])
    assert fit.coefficients_["c1"] == pytest.approx(truth["c1"], rel=0.02)
    assert fit.coefficients_["b1"] == pytest.approx(truth["b1"], rel=0.3)
    assert fit.offsets_[0] == pytest.approx(0.01, abs=3e-3)


def test_observation_gain_lag_and_gyro_bias_are_recovered():
    """angle = (1 + gain error) x(t - lag) + offset, rate = x' + bias, with x(t - lag) interpolated
    (cubic Hermite) on the simulated angle and rate."""
    truth = truth_for(("b1", "b2", "c1", "c3"))
    clean = synthetic_run(truth, seed=6, offset=0.0)
    gain, lag, bias = 1.05, 0.03, 0.004
    rng = np.random.default_rng(7)
    # the angle sensor sees gain * x(t - lag): the reference simulation started one lag earlier
    fine_t = np.concatenate([[-lag], clean.t])
    x_fine, v_fine = simulate_decay(truth, fine_t, 0.3, 0.0)
    angle = gain * np.interp(clean.t - lag, fine_t, x_fine) + 0.01 + rng.normal(0, 1e-3, clean.t.size)
    run = DecayRun(t=clean.t, angle=angle, rate=v_fine[1:] + bias + rng.normal(0, 5e-3, clean.t.size))
    fit = OutputErrorFit(tuple(truth), fit_gain=True, fit_lag=True, fit_gyro_bias=True).fit([run])
    se = np.sqrt(np.diag(fit.param_covariance_))
    names = fit.param_names_
    for name, value in (("angle_gain_error", gain - 1), ("angle_lag_s", lag), ("gyro_bias_rad_s", bias)):
        assert abs(getattr(fit, f"{name}_") - value) < Z999 * se[names.index(name)], name


def test_observation_effects_need_a_gyro():
    truth = truth_for(("b1", "c1"))
    with pytest.raises(BadIdentificationInput, match="needs a measured rate"):
        OutputErrorFit(tuple(truth), fit_gain=True).fit([synthetic_run(truth, seed=8, with_rate=False)])


@pytest.mark.slow
def test_coulomb_friction_and_exogenous_coupling_are_recovered():
    b1, c1, fc, k, eps = 0.2, 9.0, 0.05, 3.0, 1e-2
    t = np.arange(1500) / 100.0
    heave = 0.02 * np.sin(2.1 * t) * np.exp(-0.1 * t)

    def rhs(tt, y):
        return [y[1], -(b1 * y[1] + c1 * y[0] + fc * np.tanh(y[1] / eps) + k * np.interp(tt, t, heave))]

    sol = solve_ivp(rhs, (0, t[-1]), [0.2, 0.0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.005)
    rng = np.random.default_rng(9)
    run = DecayRun(
        t=t,
        angle=sol.y[0] + rng.normal(0, 1e-3, t.size),
        rate=sol.y[1] + rng.normal(0, 5e-3, t.size),
        channels={"heave_m": heave},
    )
    fit = OutputErrorFit(("b1", "c1", "fc", "ku"), exogenous="heave_m", friction_eps=eps).fit([run])
    for name, value in (("b1", b1), ("c1", c1), ("fc", fc), ("ku", k)):
        assert abs(fit.coefficients_[name] - value) < Z999 * fit.std_[name], name


def test_missing_exogenous_channel_is_an_input_error():
    truth = truth_for(("b1", "c1"))
    with pytest.raises(BadIdentificationInput, match="no channel"):
        OutputErrorFit(("b1", "c1", "ku"), exogenous="heave_m").fit([synthetic_run(truth, seed=1)])


def test_a_record_that_does_not_oscillate_is_refused():
    t = np.arange(500) / 100.0
    with pytest.raises(BadIdentificationInput, match="does not oscillate"):
        OutputErrorFit("ittc-linear").fit([DecayRun(t=t, angle=0.1 * np.exp(-t))])


def test_predict_reproduces_the_fitted_curve_and_seed_objective_is_the_one_step_rms():
    truth = truth_for(("b1", "b2", "c1", "c3"))
    run = synthetic_run(truth, seed=10)
    fit = OutputErrorFit(tuple(truth)).fit([run])
    angle, _ = fit.predict(run)
    assert np.allclose(angle, fit.fitted_[0]["angle"])
    # with the gyro noise dominating the one-step error, F ~ sqrt(2) * rate noise
    assert fit.seed_objective_ == pytest.approx(np.sqrt(2) * 5e-3, rel=0.1)


def test_a_record_cut_mid_swing_after_two_cycles_is_still_fitted():
    """A truncated end (the recording stopped early, mid-swing) only widens the intervals."""
    truth = truth_for(("b1", "b2", "c1", "c3"))
    full = synthetic_run(truth, seed=12)
    cut = full.window(0, int(4.37 * 100))  # 2.6 periods, ending between a peak and a zero crossing
    fit = OutputErrorFit(tuple(truth)).fit([cut])
    for k, value in truth.items():
        assert abs(fit.coefficients_[k] - value) < Z999 * fit.std_[k], k
    assert fit.std_["b1"] > OutputErrorFit(tuple(truth)).fit([full]).std_["b1"]


def assert_jacobian_is_central_differences(fit: OutputErrorFit, params: np.ndarray) -> None:
    """The weighted Jacobian at ``params`` column by column against central differences."""
    _, jac, _, _ = fit._model.weighted(params)
    for k, name in enumerate(fit.param_names_):
        step = 1e-6 * max(1.0, abs(params[k]))
        up, down = params.copy(), params.copy()
        up[k] += step
        down[k] -= step
        numeric = (fit._model.weighted(up)[0] - fit._model.weighted(down)[0]) / (2 * step)
        assert np.max(np.abs(numeric - jac[:, k])) < 1e-6 * np.max(np.abs(jac[:, k])), name


def test_the_full_jacobian_with_observation_parameters_equals_central_differences():
    truth = truth_for(("b1", "b2", "c1", "c3"))
    fit = OutputErrorFit(tuple(truth), fit_gain=True, fit_lag=True, fit_gyro_bias=True).fit(
        [synthetic_run(truth, seed=13, duration_s=5.0)]
    )
    params = fit.params_.copy()
    params[fit.param_names_.index("angle_lag_s")] = 0.03  # away from zero so the lag's own terms count
    assert_jacobian_is_central_differences(fit, params)


def test_the_full_jacobian_with_forcing_channels_and_ringing_equals_central_differences():
    """Input parameters (channel couplings, the ringing's frequency, decay and amplitudes) reach the
    kernel as du/dp; the lag sits between samples, so the Hermite weights and the Taylor ends count."""
    truth = truth_for(("b1", "c1"))
    run = synthetic_run(truth, seed=14, duration_s=5.0)
    run.channels = {"heave_m": 0.02 * np.sin(4.1 * run.t), "other_angle": 0.01 * np.cos(5.3 * run.t)}
    fit = OutputErrorFit(
        ("b1", "c1", "fc"),
        exogenous=("heave_m", "other_angle"),
        ringing=True,
        fit_lag=True,
        fit_gain=True,
        friction_eps=0.005,
        reweight=False,
        compute_diagnostics=False,
    ).fit([run], guess={"ring_omega_rad_s": 7.0, "ring_decay_1_s": 0.1})
    assert {"k_heave_m", "k_other_angle", "ring_omega_rad_s", "ring_cos[0]"} <= set(fit.param_names_)
    params = fit.params_.copy()
    for name, value in (("angle_lag_s", 0.037), ("ring_cos[0]", 0.3), ("ring_sin[0]", -0.2), ("fc", 0.01)):
        params[fit.param_names_.index(name)] = value
    params[fit.param_names_.index("ring_decay_1_s")] = 0.1
    params[fit.param_names_.index("ring_omega_rad_s")] = 7.0
    assert_jacobian_is_central_differences(fit, params)


def test_the_lag_interpolates_inside_and_extrapolates_beyond_the_ends():
    t = np.arange(1501) / 100.0
    omega = 3.0
    x, v = np.sin(omega * t + 0.3), omega * np.cos(omega * t + 0.3)
    acc_ends = -(omega**2) * x[[0, -1]]
    for lag in (0.004, 0.037, -0.021):
        expected = np.sin(omega * (t - lag) + 0.3)
        lagged = LagOperator(t, lag).apply(x, v, acc_ends)
        # beyond the ends a second-order Taylor step: error below |lag|^3 w^3 / 6
        assert np.max(np.abs(lagged - expected)) < abs(lag) ** 3 * omega**3 / 6 * 1.1
        inside = slice(10, -10)
        assert np.max(np.abs(lagged[inside] - expected[inside])) < 1e-7


def test_predict_before_fit_says_to_fit_first():
    from tankdaq.errors import NotFittedError

    with pytest.raises(NotFittedError, match="fit"):
        OutputErrorFit().predict(np.arange(10) / 100.0)
    with pytest.raises(NotFittedError, match="fit"):
        _ = OutputErrorFit().coefficients_
