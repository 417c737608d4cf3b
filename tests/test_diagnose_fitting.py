"""The workflow's refit engine against independent references and known truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tankdaq.diagnose.fitting import COULOMB_EPS_RAD_S, ModelSpec, fit_spec, lagged, predict, simulate_rk4
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.errors import BadIdentificationInput
from tankdaq.physics.decay import TERMS, simulate_decay
from tankdaq.records import DecayRun

T = np.arange(1501) / 100.0  # odd count: the last step is a single one


def _coef(values: dict[str, float]) -> np.ndarray:
    return np.array([values.get(k, 0.0) for k in TERMS])


@pytest.mark.parametrize(
    "coefficients",
    [
        {"b1": 0.2, "c1": 10.0},
        {"b1": 0.1, "b2": 0.4, "b3": 0.3, "c1": 9.0, "c2": 3.0, "c3": -6.0},
        {"b1": 0.15, "s1": 12.0, "s2": 1.0, "s3": 4.0},
    ],
)
def test_rk4_matches_the_reference_integrator(coefficients: dict[str, float]) -> None:
    angle_ref, rate_ref = simulate_decay(coefficients, T, 0.4)
    angle, rate = simulate_rk4(T, np.zeros(T.size), _coef(coefficients), 0.0, 0.4, 0.0)
    assert np.max(np.abs(angle - angle_ref)) < 2e-6
    assert np.max(np.abs(rate - rate_ref)) < 1e-5


def test_rk4_with_friction_and_forcing_matches_scipy() -> None:
    coefficients = {"b1": 0.1, "c1": 10.0}
    fc, k = 0.02, 3.0

    def u(t: float) -> float:
        return 0.01 * np.cos(6.0 * t)

    def rhs(t: float, y: np.ndarray) -> list[float]:
        x, v = y
        return [v, -(0.1 * v + 10.0 * x + fc * np.tanh(v / COULOMB_EPS_RAD_S) + k * u(t))]

    ref = solve_ivp(rhs, (0, T[-1]), [0.2, 0.0], t_eval=T, method="DOP853", rtol=1e-10, atol=1e-12)
    angle, rate = simulate_rk4(T, k * u(T), _coef(coefficients), fc, 0.2, 0.0)
    # the friction switch (|x'| < eps) lasts ~5 ms, shorter than a step: a tenth of the sensor noise is left
    assert np.max(np.abs(angle - ref.y[0])) < 1e-4
    assert np.max(np.abs(rate - ref.y[1])) < 1e-3
    angle, rate = simulate_rk4(T, k * u(T), _coef(coefficients), 0.0, 0.2, 0.0)
    ref = solve_ivp(
        lambda t, y: [y[1], -(0.1 * y[1] + 10.0 * y[0] + k * u(t))],
        (0, T[-1]),
        [0.2, 0.0],
        t_eval=T,
        method="DOP853",
        rtol=1e-10,
        atol=1e-12,
    )
    assert np.max(np.abs(angle - ref.y[0])) < 2e-6


def test_lagged_interpolates_and_extrapolates_a_known_function() -> None:
    omega = 3.0
    x, v = np.sin(omega * T + 0.3), omega * np.cos(omega * T + 0.3)
    for lag in (0.004, 0.037, -0.021):
        expected = np.sin(omega * (T - lag) + 0.3)
        # beyond the ends a second-order Taylor step: error below |lag|^3 w^3 / 6
        assert np.max(np.abs(lagged(T, x, v, lag) - expected)) < abs(lag) ** 3 * omega**3 / 6 * 1.1
        inside = slice(10, -10)
        assert np.max(np.abs(lagged(T, x, v, lag)[inside] - expected[inside])) < 1e-7


def test_observation_parameters_are_recovered_together() -> None:
    data = make_decay_set(["sensor.lag", "sensor.gain", "sensor.gyro_bias", "sensor.offset"], seed=11)
    spec = ModelSpec(offset=True, gain=True, lag=True, gyro_bias=True)
    truth = data.truth
    fit = fit_spec(data.runs, spec, guess={"b1": truth["b1"] * 1.2, "c1": truth["c1"] * 0.97})
    for name in ("b1", "c1", "angle_lag_s", "angle_gain_error", "gyro_bias_rad_s"):
        assert abs(fit.coefficients[name] - truth[name]) < 4 * fit.std[name] + 1e-3 * abs(truth[name]), name
        assert fit.coefficients[name] == pytest.approx(truth[name], rel=0.05), name
    assert np.mean(fit.offsets) == pytest.approx(truth["angle_offset_rad"], rel=0.05)
    assert fit.rms_angle == pytest.approx(data.noise_angle_rad, rel=0.1)
    assert fit.rms_noise_units == pytest.approx(1.0, abs=0.1)


def test_coupling_coefficient_is_recovered_from_the_measured_channel() -> None:
    data = make_decay_set(["coupling.heave"], seed=12)
    base = fit_spec(data.runs, ModelSpec(), guess={"b1": data.truth["b1"], "c1": data.truth["c1"]})
    fit = fit_spec(data.runs, ModelSpec(coupling=("heave_m",)), start=base)
    assert fit.coefficients["k_heave_m"] == pytest.approx(data.truth["k_heave_m"], rel=0.05)
    assert fit.bic < base.bic - 100


def test_predict_over_the_full_record_continues_the_fit() -> None:
    data = make_decay_set([], seed=13)
    cut = [r.window(0, 800) for r in data.runs]
    fit = fit_spec(cut, ModelSpec(), guess={"b1": data.truth["b1"], "c1": data.truth["c1"]})
    full = predict(fit, data.runs)
    for part, whole in zip(fit.runs, full, strict=True):
        np.testing.assert_allclose(whole.angle[:800], part.angle, atol=1e-12)
        assert whole.t.size == 1500
    # the model is right: the extrapolated residual stays at the noise level
    late = np.concatenate([p.residual_angle[800:] for p in full])
    assert np.sqrt(np.mean(late**2)) < 1.3 * data.noise_angle_rad
    with pytest.raises(BadIdentificationInput, match="runs"):
        predict(fit, data.runs[:2])


def test_refusals_say_what_is_missing() -> None:
    data = make_decay_set([], seed=14)
    with pytest.raises(BadIdentificationInput, match="heave_m"):
        fit_spec(data.runs, ModelSpec(coupling=("heave_m",)))
    no_rate = [DecayRun(t=r.t, angle=r.angle, name=r.name) for r in data.runs]
    with pytest.raises(BadIdentificationInput, match="measured rate"):
        fit_spec(no_rate, ModelSpec(lag=True))
    with pytest.raises(BadIdentificationInput, match="unknown decay term"):
        ModelSpec(terms=("b1", "c9"))
    with pytest.raises(BadIdentificationInput, match="no runs"):
        fit_spec([], ModelSpec())
