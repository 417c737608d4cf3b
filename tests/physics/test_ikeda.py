"""The simplified Ikeda prediction (physics.ikeda) and Froude scaling (physics.scaling).

The paper's printed worked numbers could not be found through the project's search (the paper shows
its results as figures). The reference value below is the one the public implementation
(rolldecay-estimators, ``tests/test_simplified_ikeda.py``, a conversion of the authors' Fortran)
asserts for the paper's standard ship (L/B 6, B/d 4, CB 0.65, CMID 0.98, phi_a 10 deg, bBK/B 0.025,
lBK/Lpp 0.2, OG/d -0.2, omega_hat 0.6, Lpp 300 m): an independent implementation's number, not the
paper's. The other checks are properties the formulas must have.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.errors import InputError
from tankdaq.ident.derived import b_eq, natural_period
from tankdaq.physics.decay import simulate_decay
from tankdaq.physics.ikeda import COMPONENTS, LIMITS, IkedaInputs, IkedaPrediction, components, validity
from tankdaq.physics.scaling import FroudeScale

LPP = 300.0
BEAM = LPP / 6.0
DRAFT = BEAM / 4.0
STANDARD = dict(
    lpp_m=LPP,
    beam_m=BEAM,
    draft_m=DRAFT,
    block_coefficient=0.65,
    midship_coefficient=0.98,
    og_m=-0.2 * DRAFT,
    bilge_keel_length_m=0.2 * LPP,
    bilge_keel_breadth_m=0.025 * BEAM,
)
OMEGA = 0.6 / math.sqrt(BEAM / (2 * 9.81))


def test_standard_ship_total_matches_the_public_implementation() -> None:
    found = components(IkedaInputs(**STANDARD), OMEGA, math.radians(10.0))
    assert found["B_44"] == pytest.approx(0.010156148773301035, rel=1e-9)
    assert found["B_44"] == pytest.approx(sum(found[k] for k in COMPONENTS), rel=1e-14)
    assert found["B_L"] == 0.0  # no speed, no lift


def test_eddy_grows_with_amplitude_friction_and_wave_do_not() -> None:
    inputs = IkedaInputs(**{**STANDARD, "bilge_keel_length_m": 0.0, "bilge_keel_breadth_m": 0.0})
    small, large = (components(inputs, OMEGA, math.radians(a)) for a in (5.0, 15.0))
    assert large["B_E"] == pytest.approx(3.0 * small["B_E"], rel=1e-12)  # proportional to phi_a
    assert large["B_F"] == pytest.approx(small["B_F"], rel=1e-12)  # Kato's friction: linear damping
    assert large["B_W"] == small["B_W"]
    assert small["B_BK"] == 0.0 == large["B_BK"]


def test_speed_adds_lift_raises_friction_lowers_eddy_and_says_so() -> None:
    still = IkedaInputs(**STANDARD)
    moving = IkedaInputs(**{**STANDARD, "speed_m_s": 5.0})
    a, b = (components(i, OMEGA, math.radians(10.0)) for i in (still, moving))
    assert b["B_L"] > 0.0 and b["B_F"] > a["B_F"] and b["B_E"] < a["B_E"] and b["B_W"] == a["B_W"]
    assert [f.name for f in validity(moving, OMEGA)] == ["speed"]


def test_the_standard_ship_is_inside_every_limit() -> None:
    assert validity(IkedaInputs(**STANDARD), OMEGA) == []


def _with_ratio(name: str, value: float) -> tuple[IkedaInputs, float]:
    """The standard ship with one of the paper's ratios set to ``value`` (the others unchanged)."""
    inputs, omega = dict(STANDARD), OMEGA
    if name == "CB":
        inputs["block_coefficient"] = value
    elif name == "CMID":
        inputs["midship_coefficient"] = value
    elif name == "B/d":
        inputs["draft_m"] = BEAM / value
        inputs["og_m"] = -0.2 * inputs["draft_m"]
    elif name == "OG/d":
        inputs["og_m"] = value * DRAFT
    elif name == "bBK/B":
        inputs["bilge_keel_breadth_m"] = value * BEAM
    elif name == "lBK/Lpp":
        inputs["bilge_keel_length_m"] = value * LPP
    elif name == "omega_hat":
        omega = value / math.sqrt(BEAM / (2 * 9.81))
    return IkedaInputs(**inputs), omega


@pytest.mark.parametrize("name", sorted(LIMITS))
@pytest.mark.parametrize("side", ["low", "high"])
def test_each_limit_is_named_on_both_sides(name: str, side: str) -> None:
    low, high, _ = LIMITS[name]
    if name == "omega_hat" and side == "low":  # omega_hat > 0 always: a non-positive omega is refused
        with pytest.raises(InputError, match="frequency"):
            components(IkedaInputs(**STANDARD), 0.0, 0.1)
        return
    margin = max(0.05 * abs(low if side == "low" else high), 0.001)
    value = low - margin if side == "low" else high + margin
    inputs, omega = _with_ratio(name, value)
    findings = validity(inputs, omega)
    assert [f.name for f in findings] == [name]
    assert ("below" if side == "low" else "above") in findings[0].line
    inside, omega_inside = _with_ratio(name, (low + high) / 2 if name != "omega_hat" else 0.6)
    assert validity(inside, omega_inside) == []


@pytest.mark.parametrize("name", sorted(set(LIMITS) - {"omega_hat"}))
@pytest.mark.parametrize("side", [0, 1])
def test_a_ratio_on_its_limit_is_inside_whatever_the_rounding(name: str, side: int) -> None:
    """OG = -1.5 d makes OG/d = -1.5000000000000002: on the limit, not "-1.5 below -1.5"."""
    limit = LIMITS[name][side]
    assert validity(*_with_ratio(name, limit)) == []
    if name == "OG/d":  # and at drafts whose products round the other way
        for beam_over_draft in (2.5, 3.167913730965956, 3.7, 4.5):
            draft = BEAM / beam_over_draft
            inputs = IkedaInputs(**{**STANDARD, "draft_m": draft, "og_m": limit * draft})
            assert validity(inputs, OMEGA) == [], draft


def test_bilge_keel_limits_do_not_apply_without_a_bilge_keel() -> None:
    bare = IkedaInputs(**{**STANDARD, "bilge_keel_length_m": 0.0, "bilge_keel_breadth_m": 0.0})
    assert validity(bare, OMEGA) == []


@pytest.mark.parametrize(
    "change, match",
    [
        ({"lpp_m": math.nan}, "finite"),
        ({"beam_m": -1.0}, "positive"),
        ({"speed_m_s": -0.5}, "negative"),
        ({"bilge_keel_breadth_m": 0.0}, "both"),
    ],
)
def test_bad_inputs_are_refused_in_one_line(change: dict, match: str) -> None:
    with pytest.raises(InputError, match=match):
        IkedaInputs(**{**STANDARD, **change})


def _prediction(**change: float) -> IkedaPrediction:
    inputs = IkedaInputs(**{**STANDARD, **change})
    return IkedaPrediction.at(inputs, OMEGA, total_inertia_kg_m2=2.0e10)


def test_equivalent_model_follows_ident_b_eq_convention() -> None:
    """Two amplitudes, two parameters: the fitted b1 + 8/(3 pi) omega phi b2 passes through both, and
    ident.derived.b_eq of the model gives the same B_eq/I (c1 = omega^2, so omega_E = omega)."""
    prediction = _prediction()
    amplitudes = [math.radians(5.0), math.radians(15.0)]
    model = prediction.equivalent_model(amplitudes)
    assert model["c1"] == pytest.approx(OMEGA**2, rel=1e-14)
    for a in amplitudes:
        expected = prediction.per_inertia(prediction.components(a)["B_44"])
        assert b_eq(model, a) == pytest.approx(expected, rel=1e-9)


def test_required_change_says_which_part_and_by_how_much() -> None:
    prediction = _prediction(bilge_keel_length_m=0.0, bilge_keel_breadth_m=0.0)
    amplitudes = [math.radians(a) for a in (5.0, 10.0, 15.0)]
    model = prediction.equivalent_model(amplitudes)
    b1_line, b2_line = prediction.required_change(model["b1"], 2.0 * model["b2"], amplitudes)
    assert b1_line.startswith("b1:") and "friction" in b1_line and "x1 " in b1_line
    assert b2_line.startswith("b2:") and "eddy" in b2_line and "x2 " in b2_line


# --- Froude scaling ------------------------------------------------------------------------------


def test_froude_scaling_of_periods_and_b44_is_exact_and_reverses() -> None:
    scale = FroudeScale(68.0)
    assert scale.time_s(2.53) == pytest.approx(2.53 * math.sqrt(68.0), rel=1e-15)
    assert scale.damping_n_m_s(10.0) == pytest.approx(10.0 * 68.0**4.5, rel=1e-15)
    assert scale.inverse.damping_n_m_s(scale.damping_n_m_s(3.7)) == pytest.approx(3.7, rel=1e-14)
    decay = {"b1": 0.0144, "b2": 0.0626, "b3": 0.01, "c1": 6.065, "c3": 3.9}
    ship = scale.coefficients(decay)
    assert scale.inverse.coefficients(ship) == pytest.approx(decay, rel=1e-14)
    assert natural_period(ship) == pytest.approx(scale.time_s(natural_period(decay)), rel=1e-14)
    assert ship["b2"] == decay["b2"]  # per rad of angle: no time in its unit


def test_a_simulated_model_decay_is_the_ship_decay_on_a_stretched_clock() -> None:
    scale = FroudeScale(68.0)
    model = {"b1": 0.0144, "b2": 0.0626, "c1": 6.065, "c3": 3.9}
    t_model = np.linspace(0.0, 20.0, 2001)
    angle_model, _ = simulate_decay(model, t_model, math.radians(10.0))
    angle_ship, _ = simulate_decay(scale.coefficients(model), scale.time_s(t_model), math.radians(10.0))
    assert np.max(np.abs(angle_ship - angle_model)) < 1e-8  # angles unchanged, time x sqrt(lambda)
    ups = [t_model[np.flatnonzero((a[:-1] < 0) & (a[1:] >= 0))] for a in (angle_model,)]
    period_model = float(np.mean(np.diff(ups[0])))
    crossings = np.flatnonzero((angle_ship[:-1] < 0) & (angle_ship[1:] >= 0))
    period_ship = float(np.mean(np.diff(scale.time_s(t_model)[crossings])))
    assert period_ship == pytest.approx(period_model * math.sqrt(68.0), rel=1e-12)
    assert period_model == pytest.approx(natural_period(model), rel=0.02)


@settings(max_examples=25, deadline=None)
@given(
    cb=st.floats(0.5, 0.85),
    bd=st.floats(2.5, 4.5),
    ogd=st.floats(-1.5, 0.2),
    cm=st.floats(0.9, 0.99),
    bbkb=st.floats(0.01, 0.06),
    lbkl=st.floats(0.05, 0.4),
    omega_hat=st.floats(0.2, 1.0),
    amplitude_deg=st.floats(1.0, 30.0),
)
def test_inside_the_limits_every_component_is_finite_and_no_finding(
    cb: float,
    bd: float,
    ogd: float,
    cm: float,
    bbkb: float,
    lbkl: float,
    omega_hat: float,
    amplitude_deg: float,
) -> None:
    draft = BEAM / bd
    inputs = IkedaInputs(
        lpp_m=LPP, beam_m=BEAM, draft_m=draft, block_coefficient=cb, midship_coefficient=cm, og_m=ogd * draft,
        bilge_keel_length_m=lbkl * LPP, bilge_keel_breadth_m=bbkb * BEAM,
    )  # fmt: skip
    omega = omega_hat / math.sqrt(BEAM / (2 * 9.81))
    found = components(inputs, omega, math.radians(amplitude_deg))
    assert all(math.isfinite(v) for v in found.values())
    assert found["B_F"] > 0 and found["B_W"] >= 0 and found["B_L"] == 0.0
    assert validity(inputs, omega) == []
