"""Full scale the ITTC way (physics.friction_scaling, ident.full_scale): the water, the round trip, KVLCC2
against a hand calculation, and bad assumptions refused."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

import tankdaq
from tankdaq.api.identification import Identification, Reading
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.cli import app
from tankdaq.config.hulls import load_hull
from tankdaq.errors import InputError
from tankdaq.ident.full_scale import full_scale_b44
from tankdaq.physics.friction_scaling import (
    FrictionScaling,
    Water,
    WaterKind,
    fresh_water_viscosity,
    sea_water_viscosity,
)
from tankdaq.physics.kato import Kato
from tankdaq.physics.scaling import FroudeScale

runner = CliRunner()
DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay"
needs_kvlcc2 = pytest.mark.skipif(
    not (DATA / "model_test_21338.csv").is_file() or not (DATA / "model_test_parameters.csv").is_file(),
    reason=f"the KVLCC2 data is not at {DATA}",
)

#: ITTC 7.5-02-01-03 (2011), "Fresh Water and Seawater Properties": kinematic viscosity (m²/s) of sea water
#: (absolute salinity 35.16504 g/kg) and fresh water at the table's temperatures (°C).
ITTC_SEA = {
    1: 1.7926e-6,
    5: 1.5762e-6,
    10: 1.3604e-6,
    15: 1.1892e-6,
    20: 1.0508e-6,
    25: 9.3713e-7,
    30: 8.4253e-7,
}
ITTC_FRESH = {10: 1.3063e-6, 15: 1.1386e-6, 20: 1.0034e-6}
#: The formulas reproduce the table to 0.03 % (its printed digits and the fits' own accuracy).
TABLE_ACCURACY = 3e-4


@pytest.mark.parametrize("temperature_c, table", sorted(ITTC_SEA.items()))
def test_sea_water_viscosity_is_the_ittc_table(temperature_c: float, table: float) -> None:
    assert sea_water_viscosity(temperature_c) == pytest.approx(table, rel=TABLE_ACCURACY)


@pytest.mark.parametrize("temperature_c, table", sorted(ITTC_FRESH.items()))
def test_fresh_water_viscosity_is_the_ittc_table(temperature_c: float, table: float) -> None:
    assert fresh_water_viscosity(temperature_c) == pytest.approx(table, rel=TABLE_ACCURACY)


@pytest.mark.parametrize("temperature_c", [-1.0, 40.5, 288.15, math.nan, math.inf])
def test_a_temperature_the_tables_do_not_hold_is_refused(temperature_c: float) -> None:
    with pytest.raises(InputError, match="give a water temperature of 0 to 40 degC"):
        sea_water_viscosity(temperature_c)
    with pytest.raises(InputError, match="give a water temperature of 0 to 40 degC"):
        fresh_water_viscosity(temperature_c)


def _scaling(scale: float = 40.0, speed_m_s: float = 0.6) -> FrictionScaling:
    """A 4 m model (L/B 6, B/d 4, CB 0.65) in 20 degC tank water, its ship in 10 degC sea."""
    kato = Kato(lpp_m=4.0, beam_m=0.6667, draft_m=0.1667, block_coefficient=0.65, og_m=-0.02)
    model = Water.at(WaterKind.FRESH, 20.0, "test")
    ship = Water.at(WaterKind.SEA, 10.0, "test")
    return FrictionScaling(FroudeScale(scale), kato, speed_m_s, model, ship, 1000.0)


def test_full_scale_and_back_gives_the_model_again() -> None:
    """Coefficients by Froude and B44 friction-corrected, to the ship and back: the model's, unchanged."""
    coefficients = {"b1": 0.031, "b2": 0.12, "b3": 0.4, "c1": 14.0, "c3": -3.0}
    froude = FroudeScale(40.0)
    assert froude.inverse.coefficients(froude.coefficients(coefficients)) == pytest.approx(
        coefficients, rel=1e-12
    )
    scaling, inertia = _scaling(), 3.2
    ship_coefficients, ship_inertia = froude.coefficients(coefficients), froude.inertia_kg_m2(inertia)
    for amplitude in (0.02, 0.1, 0.3):
        there = full_scale_b44(coefficients, amplitude, inertia, scaling)
        assert there.correction_n_m_s < 0  # friction is a smaller share of a ship's damping
        ship_omega = math.sqrt(ship_coefficients["c1"] + 0.75 * ship_coefficients["c3"] * amplitude**2)
        back = scaling.inverse.at(there.corrected_n_m_s, ship_omega, amplitude)
        model_b44 = full_scale_b44(coefficients, amplitude, inertia, scaling).froude_n_m_s / 40.0**4.5
        assert back.corrected_n_m_s == pytest.approx(model_b44, rel=1e-9)
        assert back.reynolds_model == pytest.approx(there.reynolds_ship, rel=1e-12)
        # the ship's corrected B44 per its inertia, as the ship's own decay would show it
        ship_b44 = full_scale_b44(ship_coefficients, amplitude, ship_inertia, scaling.inverse).froude_n_m_s
        assert ship_b44 * 40.0**4.5 == pytest.approx(there.froude_n_m_s, rel=1e-9)


def test_the_speed_factor_is_the_same_at_both_scales() -> None:
    """Ikeda's 1 + 4.1 U/(ωL) is Froude-invariant: speed raises both friction components alike."""
    still, moving = _scaling(speed_m_s=0.0).at(100.0, 2.5, 0.15), _scaling(speed_m_s=0.6).at(100.0, 2.5, 0.15)
    factor = 1 + 4.1 * 0.6 / (2.5 * 4.0)
    assert moving.friction_model_n_m_s == pytest.approx(still.friction_model_n_m_s * factor, rel=1e-12)
    assert moving.friction_ship_n_m_s == pytest.approx(still.friction_ship_n_m_s * factor, rel=1e-12)


@pytest.fixture(scope="module")
def kvlcc2() -> Identification:
    reading = Reading(time_col="time", angle_col="phi", angle_unit="rad")
    return tankdaq.identify(DATA / "model_test_21338.csv", hull="kvlcc2", full_scale=True, reading=reading)


def _kato_by_hand(rho: float, r: float, s: float, phi: float, w: float, nu: float) -> tuple[float, float]:
    """B_F = 4/(3π) ρ S_f r_f³ φa ω C_f, C_f = 1.328 Re^-0.5 + 0.014 Re^-0.114, Re = 3.22 r_f² φa² / (T ν)."""
    period = 2 * math.pi / w
    reynolds = 3.22 * r**2 * phi**2 / (period * nu)
    cf = 1.328 * reynolds**-0.5 + 0.014 * reynolds**-0.114
    return 4 / (3 * math.pi) * rho * s * r**3 * phi * w * cf, reynolds


@needs_kvlcc2
@pytest.mark.slow
def test_kvlcc2_friction_correction_matches_a_hand_calculation(kvlcc2: Identification) -> None:
    """Kato's B_F of SSPA's KVLCC2 model at the model's and the ship's Reynolds number, worked out here from
    the parameters file by the formulas of ITTC 7.5-02-07-04.5 (15 degC fresh and sea water, ITTC's
    table), against what identify shows: the correction's sign, size and Reynolds numbers."""
    with (DATA / "model_test_parameters.csv").open() as f:
        row = next(r for r in csv.DictReader(f) if r["id"] == "21338")
    lam, rho, g = float(row["scale_factor"]), float(row["rho"]), float(row["g"])
    lpp, beam, draft = float(row["lpp"]) / lam, float(row["beam"]) / lam, float(row["TA"]) / lam
    volume, kg, gm = float(row["Volume"]) / lam**3, float(row["kg"]) / lam, float(row["gm"]) / lam
    cb = volume / (lpp * beam * draft)
    og = draft - kg  # still water level to G, downward positive
    radius = draft * ((0.887 + 0.145 * cb) * (1.7 + cb * beam / draft) - 2 * og / draft) / math.pi
    surface = lpp * (1.75 * draft + cb * beam)
    nu_fresh, nu_sea = ITTC_FRESH[15], ITTC_SEA[15]
    document = json.loads(kvlcc2.to_json())
    c = {k: v["value"] for k, v in document["coefficients"].items()}
    assert set(c) <= {"b1", "b2", "b3", "c1", "c3"}
    inertia = rho * volume * g * gm / c["c1"]
    ship = document["full_scale"]
    assert ship["friction"]["model_speed_m_s"] == 0.0  # run 21338 is at 0 kn
    for model, full in zip(document["b_eq"], ship["b_eq"], strict=True):
        phi = math.radians(model["amplitude_deg"])
        omega = math.sqrt(c["c1"] + 0.75 * c.get("c3", 0.0) * phi**2)  # ω_E of c1 φ + c3 φ³

        b_f_model, re_model = _kato_by_hand(rho, radius, surface, phi, omega, nu_fresh)
        ship_omega = omega / math.sqrt(lam)
        b_f_ship, re_ship = _kato_by_hand(rho, radius * lam, surface * lam**2, phi, ship_omega, nu_sea)
        correction = b_f_ship - lam**4.5 * b_f_model
        froude = model["value_per_s"] * inertia * lam**4.5
        assert full["reynolds_model"] == pytest.approx(re_model, rel=1e-3)
        assert full["reynolds_ship"] == pytest.approx(re_ship, rel=1e-3)
        assert re_ship == pytest.approx(re_model * lam**1.5 * nu_fresh / nu_sea, rel=1e-9)
        assert full["friction_correction_n_m_s"] == pytest.approx(correction, rel=1e-3)
        assert full["b44_corrected_n_m_s"] == pytest.approx(froude + correction, rel=1e-3)
        assert full["friction_share"] == pytest.approx(correction / froude, rel=1e-3)
        assert correction < 0 and -0.5 < correction / froude < 0  # by Froude alone, friction is too large
    text = kvlcc2.text()
    (head,) = [i for i, line in enumerate(text.splitlines()) if "Re model" in line and "Re ship" in line]
    rows = text.splitlines()[head + 1 : head + 1 + len(ship["b_eq"])]
    for full, shown in zip(ship["b_eq"], rows, strict=True):
        amplitude, _, _, froude_b44, corrected, correction_text, share, re_m, re_s = shown.split()
        assert float(amplitude) == pytest.approx(full["amplitude_deg"], abs=0.006)
        assert float(froude_b44) == pytest.approx(full["b_eq_n_m_s"], rel=1e-3)
        assert float(corrected) == pytest.approx(full["b44_corrected_n_m_s"], rel=1e-3)
        assert float(correction_text) == pytest.approx(full["friction_correction_n_m_s"], rel=1e-3)
        assert float(share.rstrip("%")) == pytest.approx(100 * full["friction_share"], abs=0.06)
        assert float(re_m) == pytest.approx(full["reynolds_model"], rel=1e-2)
        assert float(re_s) == pytest.approx(full["reynolds_ship"], rel=1e-2)
    assert "fresh water 15 degC" in text and "sea water 15 degC" in text and "7.5-02-01-03" in text
    table = kvlcc2.full_scale
    assert list(table["b44_corrected_n_m_s"]) == [r["b44_corrected_n_m_s"] for r in ship["b_eq"]]


def _refused_in_one_line(result: Result, message: str) -> None:
    """Exit 2 with one line that says what to do, and nothing else."""
    assert result.exit_code == 2, result.output
    assert message in result.output and len(result.output.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--water-temperature", "288"], "--water-temperature 288: give a water temperature of 0 to 40 degC"),
        (["--sea-temperature", "-3"], "--sea-temperature -3: give a water temperature of 0 to 40 degC"),
        (["--sea-temperature", "nan"], "--sea-temperature nan: give a water temperature of 0 to 40 degC"),
    ],
)
@pytest.mark.slow
def test_bad_water_temperatures_are_refused_before_any_work(
    tmp_path: Path, extra: list[str], message: str
) -> None:
    data = tmp_path / "never-read.csv"
    data.write_text("not a decay\n")
    for command in ("identify", "campaign"):
        result = runner.invoke(app, [command, str(data), "--hull", "kvlcc2", "--full-scale", *extra])
        _refused_in_one_line(result, message)


@pytest.mark.parametrize(
    "key, message",
    [
        (
            "water_temperature_c = 291.15",
            "water_temperature_c 291.15: give a water temperature of 0 to 40 degC",
        ),
        ("sea_temperature_c = -5", "sea_temperature_c -5: give a water temperature of 0 to 40 degC"),
        ("sea_kinematic_viscosity_m2_s = 1.19", "sea_kinematic_viscosity_m2_s = 1.19 is outside"),
    ],
)
@pytest.mark.slow
def test_bad_water_keys_in_a_hull_are_refused_in_one_line(tmp_path: Path, key: str, message: str) -> None:
    shipped = load_hull("kvlcc2").path
    assert shipped is not None
    hull = tmp_path / "kv.toml"
    hull.write_text(shipped.read_text().replace("scale_factor = 68.0", f"scale_factor = 68.0\n{key}"))
    data = tmp_path / "never-read.csv"
    data.write_text("not a decay\n")
    result = runner.invoke(app, ["identify", str(data), "--hull", str(hull), "--full-scale"])
    _refused_in_one_line(result, message)
    with pytest.raises(InputError, match=r"water temperature|outside"):
        tankdaq.identify(data, hull=hull, full_scale=True)


@pytest.mark.parametrize("name", ["water_temperature_c", "sea_temperature_c"])
def test_the_api_refuses_bad_temperatures_by_name(tmp_path: Path, name: str) -> None:
    data = tmp_path / "never-read.csv"
    data.write_text("not a decay\n")
    with pytest.raises(InputError, match=name):
        tankdaq.identify(data, hull="kvlcc2", full_scale=True, **{name: 45.0})


@pytest.mark.slow
def test_campaign_shows_both_columns_and_the_water_it_assumed(tmp_path: Path, monkeypatch) -> None:
    """A roll group whose hull gives the particulars: Froude and friction-corrected B44 on its line, the
    correction adding up, and the water each side was taken at (the hull's key, the option)."""
    hulls = tmp_path / "hulls"
    hulls.mkdir()
    shipped = load_hull("swath").path
    assert shipped is not None
    particulars = "scale_factor = 16.0\nlpp_m = 2.0\nbeam_m = 0.6\ndraft_m = 0.15\n"
    particulars += "block_coefficient = 0.5\nkg_m = 0.2\n"
    (hulls / "swath.toml").write_text(
        f"{shipped.read_text()}\n[particulars]\n{particulars}water_temperature_c = 18.0\n"
    )
    monkeypatch.setenv("TANKDAQ_HULLS_DIR", str(hulls))
    write_simulated_campaign(tmp_path / "runs", ["swath"], "roll", [1.0], [6.0], "csv", seed=3)
    result = runner.invoke(app, ["campaign", str(tmp_path / "runs"), "--jobs", "1", "--full-scale",
                                 "--sea-temperature", "12"])  # fmt: skip
    assert result.exit_code == 0, result.output
    (line,) = [x for x in result.stdout.splitlines() if x.startswith("swath") and "1:16" in x]
    froude = float(line.split("B44 ")[1].split(" ")[0])
    corrected = float(line.split("friction-corrected ")[1].split(" ")[0])
    correction = float(line.split("(correction ")[1].split(" ")[0])
    share = float(line.split("N·m·s/rad, ")[-1].split("%")[0])
    assert corrected == pytest.approx(froude + correction, rel=1e-3) and correction < 0
    assert share == pytest.approx(100 * correction / froude, abs=0.06)
    reynolds_model = float(line.split("Reynolds ")[1].split(" model")[0])
    reynolds_ship = float(line.split("model, ")[1].split(" ship")[0])
    water = fresh_water_viscosity(18.0) / sea_water_viscosity(12.0)
    assert reynolds_ship == pytest.approx(reynolds_model * 16.0**1.5 * water, rel=1e-2)  # printed to 3 digits
    assert "fresh water 18 degC (water_temperature_c in" in result.stdout
    assert "sea water 12 degC (--sea-temperature)" in result.stdout
