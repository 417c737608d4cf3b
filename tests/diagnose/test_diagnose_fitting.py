"""The workflow's model variants, fitted by ident's output-error engine, against known truth.

The engine itself (integrator, sensitivities, lag interpolation) is tested in test_ident_kernels and
test_ident_output_error."""

from __future__ import annotations

import numpy as np
import pytest

from tankdaq.diagnose.fitting import ModelSpec, fit_spec, predict
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.errors import BadIdentificationInput
from tankdaq.records import DecayRun


@pytest.mark.slow
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


@pytest.mark.slow
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
