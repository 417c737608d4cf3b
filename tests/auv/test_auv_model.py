"""Diving-plane model: vehicle files, prime scaling, trim, the zigzag switching rule, replay."""

from __future__ import annotations

import numpy as np
import pytest

from tankdaq.auv.model import (
    REALISTIC_NOISE_STD,
    STATE_COLUMNS,
    _rhs,
    add_noise,
    pack_parameters,
    replay,
    simulate_zigzag,
    trim_state,
)
from tankdaq.auv.vehicle import TERM_BY_NAME, VISCOUS_TERMS, list_vehicles, load_vehicle
from tankdaq.errors import InputError


def test_both_public_vehicles_are_configured_with_a_source_for_every_value():
    assert {"nps_auv2", "remus100"} <= set(list_vehicles())
    for name in ("nps_auv2", "remus100"):
        vehicle = load_vehicle(name)
        for key in vehicle.derivatives:
            assert vehicle.sources.get(key), f"{name}: {key} has no source"
        assert vehicle.sources.get("iy_kg_m2") and vehicle.sources.get("bg_m")


def test_unknown_vehicle_lists_the_known_ones():
    with pytest.raises(InputError) as info:
        load_vehicle("seaglider")
    message = str(info.value)
    assert "seaglider" in message and "nps_auv2" in message and "remus100" in message
    assert info.value.exit_code == 2


def test_dimensional_remus_values_become_prime_values_by_rho_half_length_powers():
    remus = load_vehicle("remus100")
    # Prestero: M_q|q| = -188 N m s^2 multiplies q|q|, a rho/2 L^5 term; Z_uw = -28.6 kg/m a rho/2 L^2 term.
    assert remus.coefficient("M_q|q|") == pytest.approx(-188.0 / (0.5 * 1030.0 * 1.33**5), rel=1e-12)
    assert remus.coefficient("Z_uw") == pytest.approx(-28.6 / (0.5 * 1030.0 * 1.33**2), rel=1e-12)
    power = TERM_BY_NAME["M_q|q|"].length_power
    assert remus.scale(power) * remus.coefficient("M_q|q|") == pytest.approx(-188.0)


def test_nps_prime_values_are_taken_as_published():
    nps = load_vehicle("nps_auv2")
    assert nps.coefficient("M_uw") == 0.1 and nps.coefficient("Z_wdot") == -0.24
    assert nps.mass_kg == pytest.approx(53400 / 9.81)


@pytest.mark.parametrize("name", ["nps_auv2", "remus100"])
def test_trim_is_a_steady_level_state(name):
    vehicle = load_vehicle(name)
    trim = trim_state(vehicle)
    rates = _rhs(pack_parameters(vehicle), trim, trim[6], trim[6])
    assert np.max(np.abs(rates[[0, 1, 2, 3, 4]])) < 1e-9
    if name == "nps_auv2":  # neutrally buoyant and symmetric: trimmed with everything at zero
        assert trim[0] == pytest.approx(vehicle.nominal_speed_m_s) and np.allclose(trim[1:], 0, atol=1e-12)
    else:  # REMUS is 9 N light and needs nose-down plane and pitch to hold depth
        assert trim[6] < 0 and trim[3] < 0


def test_zigzag_reverses_the_plane_exactly_at_the_pitch_threshold():
    vehicle = load_vehicle("nps_auv2")
    delta, theta = np.radians(15.0), np.radians(10.0)
    record = simulate_zigzag(vehicle, delta, theta, switches=6, rate_hz=50.0)
    assert record.switch_times.size == 7  # six applied reversals and the final one that ends the record
    pitch_at_switch = np.interp(record.switch_times, record.t, record["theta"])[:-1]
    expected = -theta * np.array([1, -1, 1, -1, 1, -1])
    # interpolating 50 Hz samples limits the check to a small fraction of a degree
    assert np.allclose(pitch_at_switch, expected, atol=np.radians(0.05))
    plane = record["delta_s"]
    assert plane.max() == pytest.approx(delta, rel=1e-3) and plane.min() == pytest.approx(-delta, rel=1e-3)
    assert record.t[-1] <= record.switch_times[-1]


def test_too_weak_plane_is_refused_with_a_hint():
    with pytest.raises(InputError, match="increase --delta or lower --theta"):
        simulate_zigzag(load_vehicle("nps_auv2"), np.radians(1.0), np.radians(30.0))
    with pytest.raises(InputError, match="plane limit"):
        simulate_zigzag(load_vehicle("nps_auv2"), np.radians(25.0), np.radians(10.0))


def test_replay_of_the_recorded_plane_reproduces_the_zigzag():
    vehicle = load_vehicle("remus100")
    record = simulate_zigzag(vehicle, np.radians(10.0), np.radians(5.0), rate_hz=100.0)
    start = np.array([record[c][0] for c in STATE_COLUMNS])
    again = replay(vehicle, record.t, record["delta_s"], start)
    # the replay interpolates the plane linearly between samples: close but not bit-identical
    assert np.max(np.abs(again["theta"] - record["theta"])) < np.radians(0.2)
    assert np.max(np.abs(again["z"] - record["z"])) < 0.01


def test_noise_has_the_stated_size_per_channel():
    record = simulate_zigzag(load_vehicle("nps_auv2"), np.radians(15.0), np.radians(10.0), rate_hz=100.0)
    noisy = add_noise(record, 2.0, seed=3)
    for column in STATE_COLUMNS:
        measured = np.std(noisy[column] - record[column])
        assert measured == pytest.approx(2.0 * REALISTIC_NOISE_STD[column], rel=0.05)
    assert noisy.meta["noise"] == "2"


def test_every_viscous_term_has_an_equation_and_scaling():
    for name in VISCOUS_TERMS:
        term = TERM_BY_NAME[name]
        assert term.equation in "XZM" and 2 <= term.length_power <= 5 and not term.inertia
