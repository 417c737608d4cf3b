"""The uncertainty budget (issue 38): it adds up, a source removed removes its row, Monte Carlo agrees,
its Type A comes from repeats, the hull's uncertainties are checked where they enter, U covers the
truth over simulated campaigns (a few here, 200 in bench/bench_budget_coverage.py), and the real
KVLCC2 decay's budget is finite and plausible."""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import tankdaq
from tankdaq.config.hulls import load_hull
from tankdaq.errors import ConfigError
from tankdaq.ident.budget import EXPANDED_LABEL, FitUncertainty, budgets, monte_carlo, without
from tankdaq.ident.budget_fit import fit_budgets, hull_figures, per_decay_coefficients
from tankdaq.ident.budget_inputs import (
    MTI_G_710,
    device_sources,
    hull_sources,
    nominal_inputs,
    reported_quantities,
)
from tankdaq.ident.derived import tested_amplitudes_deg as band_of
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.records import DecayRun

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from support.budget_coverage import campaign, coverage, truth

KVLCC2 = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)
#: A hull with every uncertainty the budget reads (the catamaran's figures, its simulation included).
UNCERTAIN_HULL = """
name = "uncertain"
description = "the catamaran with uncertainties"
[dimensions]
beam_m = 0.5
displacement_kg = 15.0
displacement_uncertainty_kg = 0.05
[axes.roll]
gm_m = 0.2
gm_uncertainty_m = 0.002
radius_of_gyration_m = 0.175
radius_of_gyration_uncertainty_m = 0.005
[particulars]
added_inertia_fraction = 0.28
scale_factor = 20.0
[simulation.roll.drafts."T"]
b1 = 1.0
b2 = 0.8
c1 = 50.0
c3 = -20.0
"""


def _decays(count: int, seed: int = 3) -> list[DecayRun]:
    from tankdaq.campaign.synthetic import SimulatedTest, simulated_decay

    test = SimulatedTest(duration_s=8.0, hold_s=0.2)
    rng = np.random.default_rng(seed)
    runs = []
    for i in range(count):
        t, angle, rate = simulated_decay(truth(), 10.0, test, rng)
        k = test.release_index
        runs.append(DecayRun(t=t[k:] - t[k], angle=angle[k:], rate=rate[k:], axis="roll", name=f"run{i}"))
    return runs


@pytest.fixture(scope="module")
def hull(tmp_path_factory: pytest.TempPathFactory) -> object:
    path = tmp_path_factory.mktemp("hull") / "uncertain.toml"
    path.write_text(UNCERTAIN_HULL)
    return load_hull(str(path))


@pytest.fixture(scope="module")
def fitted() -> tuple[OutputErrorFit, list[DecayRun]]:
    runs = _decays(3)
    return OutputErrorFit(sorted(truth())).fit(runs), runs


def test_the_budget_adds_up_and_a_source_removed_removes_its_row(fitted, hull) -> None:
    fit, runs = fitted
    figures = hull_figures(hull, "roll", 1.0, scale_factor=20.0)
    found = fit_budgets(fit, runs, band_of(runs, fit.offsets_), figures, MTI_G_710)
    keys = {b.key for b in found}
    assert {"natural_period_s", "b_eq_per_s@5", "gm_implied_m", "b44_hat@5", "full_scale_b44_n_m_s@5"} <= keys
    for b in found:
        total = math.sqrt(sum(r.contribution**2 for r in b.rows))
        assert abs(total - b.combined) <= 1e-9 * b.combined
        assert b.expanded == pytest.approx(2.0 * b.combined, rel=1e-12)
        assert sum(r.share for r in b.rows) == pytest.approx(1.0, rel=1e-9)
        for r in b.rows:
            assert r.contribution == pytest.approx(abs(r.sensitivity) * r.u, rel=1e-12)
    by_key = {b.key: b for b in found}
    hat_sources = {r.source for r in by_key["b44_hat@5"].rows}
    assert {"GM", "angle accuracy (MTi-G-710)"} <= hat_sources  # the displacement cancels in B̂44
    assert "roll gyradius" in {r.source for r in by_key["gm_implied_m"].rows}
    assert {"GM", "displacement"} <= {r.source for r in by_key["full_scale_b44_n_m_s@5"].rows}
    assert "GM" not in {r.source for r in by_key["natural_period_s"].rows}
    # the hull's GM uncertainty removed: its row goes, u_c falls by exactly its contribution
    full = by_key["b44_hat@5"]
    gm_row = next(r for r in full.rows if r.source == "GM")
    fewer = fit_budgets(
        fit,
        runs,
        band_of(runs, fit.offsets_),
        replace(figures, gm_u=None),
        MTI_G_710,
        per_decay=per_decay_coefficients(fit, runs),
    )
    hat = next(b for b in fewer if b.key == "b44_hat@5")
    assert "GM" not in {r.source for r in hat.rows}
    assert hat.combined**2 == pytest.approx(full.combined**2 - gm_row.contribution**2, rel=1e-9)
    assert without(full, "GM").combined == pytest.approx(hat.combined, rel=1e-9)


def test_type_a_is_from_repeats_or_says_that_repeats_are_needed(fitted) -> None:
    fit, runs = fitted
    tested = band_of(runs, fit.offsets_)
    three = {b.key: b for b in fit_budgets(fit, runs, tested)}["natural_period_s"]
    assert three.rows[0].kind.value == "A" and "n=3" in three.rows[0].source
    assert any("3 repeat decays" in note for note in three.notes)
    one = OutputErrorFit(fit.terms_).fit(runs[:1])
    alone = {b.key: b for b in fit_budgets(one, runs[:1], tested)}["natural_period_s"]
    assert alone.rows[0].source.startswith("the fit (hac")
    assert any("repeat the decay" in note for note in alone.notes)
    pooled = [replace(run, meta={**run.meta, "hull": hull}) for run, hull in zip(runs, "abb", strict=True)]
    assert per_decay_coefficients(fit, pooled) == ()  # --joint: decays of two hulls are not repeats
    joint = {b.key: b for b in fit_budgets(fit, runs, tested, per_decay=())}["natural_period_s"]  # GA, PSO
    assert joint.rows[0].note == "3 decays fitted together" and not any(
        "repeat the" in n for n in joint.notes
    )


@pytest.mark.slow
def test_monte_carlo_agrees_with_the_sensitivities(fitted, hull) -> None:
    fit, runs = fitted
    figures = hull_figures(hull, "roll", 1.0)
    quantities = {q.key: q for q in reported_quantities(fit.terms_, "roll", [5.0], figures)}
    inputs = nominal_inputs(figures)
    sources = device_sources(MTI_G_710, 10.0, 8.0) + hull_sources(figures)
    for decays in ((), per_decay_coefficients(fit, runs)):  # the fit's covariance, then the repeats
        state = FitUncertainty({k: fit.coefficients_[k] for k in fit.terms_}, fit.covariance_, "hac", decays)
        for key in ("natural_period_s", "b_eq_per_s@5", "b44_hat@5"):
            (linear,) = budgets([quantities[key]], state, inputs, sources)
            std, low, high = monte_carlo(quantities[key], state, inputs, sources, draws=1500, seed=1)
            assert std == pytest.approx(linear.combined, rel=0.08), key  # 1500 draws: std known to 1.8 %
            assert low < linear.value < high


@pytest.mark.parametrize(
    ("lines", "said"),
    [
        ("[axes.roll]\ngm_m = 0.2\ngm_uncertainty_m = -0.01", "gm_uncertainty_m"),
        ("[axes.roll]\ngm_m = 0.2\ngm_uncertainty_m = 0.3", "gm_uncertainty_m"),
        ("[axes.roll]\nradius_of_gyration_uncertainty_m = 0.01", "without radius_of_gyration_m"),
        (
            "[dimensions]\ndisplacement_kg = 15.0\ndisplacement_uncertainty_kg = 15.0",
            "displacement_uncertainty_kg",
        ),
        ("[dimensions]\ndisplacement_uncertainty_kg = 0.1", "without displacement_kg"),
    ],
)
def test_a_hull_uncertainty_is_checked_where_it_enters(tmp_path: Path, lines: str, said: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(f'name = "bad"\ndescription = "x"\n{lines}\n')
    with pytest.raises(ConfigError, match=said) as caught:
        load_hull(str(path))
    assert "\n" not in str(caught.value)


def test_identify_shows_the_budget_in_text_json_and_a_dataframe(hull, tmp_path: Path) -> None:
    runs = _decays(1, seed=5)
    result = tankdaq.identify(runs, model="b1,b2,c1,c3", hull=hull.path)
    table = result.budget
    assert {"quantity", "source", "kind", "u", "sensitivity", "contribution", "share", "expanded_u"} <= set(
        table
    )
    period = table[table["quantity"] == "natural period"]
    assert period["expanded_u"].iloc[0] == pytest.approx(2 * period["combined_u"].iloc[0])
    assert set(table["kind"]) == {"A", "B"}
    document = json.loads(result.to_json())
    assert document["budget"][0]["labels"]["expanded_u"] == EXPANDED_LABEL
    assert EXPANDED_LABEL in result.text() and "repeat the decay" in result.text()


@pytest.mark.slow
def test_expanded_uncertainty_covers_the_truth_in_simulated_campaigns() -> None:
    """12 campaigns of 3 repeats (200 in bench/bench_budget_coverage.py). If U covers the truth in 95 %,
    9 or fewer of 12 covered has a chance of 0.2 %; the RMS of error / u_c of a right budget is near 1
    (below 1 where the larger Type A is counted), and far below 0.4 only if U is several times too wide."""
    coefficients = truth()
    found = coverage([campaign(seed, coefficients) for seed in range(1000, 1012)])
    for key, figures in found.items():
        assert figures["covered"] >= 9 / 12, (key, figures)
        assert 0.4 < figures["rms_error_over_u"] < 1.6, (key, figures)


@pytest.mark.skipif(not KVLCC2.is_file(), reason=f"the KVLCC2 roll decay is not at {KVLCC2}")
@pytest.mark.slow
def test_the_kvlcc2_decay_has_a_finite_plausible_budget() -> None:
    from tankdaq.api.identification import Reading

    reading = Reading(time_col="time", angle_col="phi", rate_col=None)
    result = tankdaq.identify(KVLCC2, model="b1,b2,c1,c3", hull="kvlcc2", full_scale=True, reading=reading)
    table = result.budget
    assert np.isfinite(table[["value", "u", "sensitivity", "contribution", "combined_u"]].to_numpy()).all()
    period = table[table["quantity"] == "natural period"].iloc[0]
    # one 2.55 s decay of many cycles: its period is known to better than 1 %, but not to 1e-6
    assert 2.4 < period["value"] < 2.7
    assert 1e-6 * period["value"] < period["expanded_u"] < 0.01 * period["value"]
    assert {"B_eq/I at 5 deg", "B̂44 at 5 deg", "full-scale B44 at 5 deg"} <= set(table["quantity"])


@pytest.mark.slow
def test_the_catalogue_keeps_each_fits_budget(catalogue_url: str, tmp_path: Path) -> None:
    """A campaign's group fit (Type A from its two repeats) and an identify fit (one decay) each keep
    their budget in ``budgets``, a row per quantity and source that adds up as the fit's own did."""
    import sqlalchemy as sa
    from typer.testing import CliRunner

    from tankdaq.campaign.synthetic import SimulatedTest, write_simulated_campaign
    from tankdaq.catalogue.database import open_catalogue
    from tankdaq.catalogue.schema import budgets, fits
    from tankdaq.cli import app

    test = SimulatedTest(duration_s=6.0)
    paths = [
        write_simulated_campaign(tmp_path / "rec" / f"r{seed}", ["catamaran"], "roll", [1.0], [10.0], "mcap",
                                 test=test, seed=seed)[0]
        for seed in range(2)
    ]  # fmt: skip
    for args in (["campaign", str(tmp_path / "rec")], ["identify", str(paths[0]), "--json"]):
        done = CliRunner().invoke(app, [*args, "--catalogue", catalogue_url])
        assert done.exit_code == 0, done.output
    said = json.loads(done.stdout)
    with open_catalogue(catalogue_url) as catalogue, catalogue.reading() as connection:
        kept = {row.id: row.source for row in connection.execute(sa.select(fits.c.id, fits.c.source))}
        rows = [r._mapping for r in connection.execute(sa.select(budgets).order_by(budgets.c.id))]
    assert sorted(kept.values()) == ["campaign", "campaign", "identify"]
    assert {r["fit_id"] for r in rows} == set(kept)
    for fit_id, source in kept.items():
        period = [r for r in rows if r["fit_id"] == fit_id and r["quantity_key"] == "natural_period_s"]
        assert period[0]["kind"] == "A" and ("n=2" in period[0]["source"]) == (source == "campaign")
        total = math.sqrt(sum(r["contribution"] ** 2 for r in period))
        assert total == pytest.approx(period[0]["combined_u"], rel=1e-9)
        assert period[0]["expanded_u"] == pytest.approx(2 * total, rel=1e-9)
    identify_id = next(i for i, s in kept.items() if s == "identify")
    stored = next(r for r in rows if r["fit_id"] == identify_id and r["quantity_key"] == "natural_period_s")
    assert stored["expanded_u"] == pytest.approx(said["budget"][0]["expanded_u"], rel=1e-12)


def test_the_device_profile_follows_the_recordings_product_code(tmp_path: Path) -> None:
    """A recording made with a 2007-era MTi-G gets its datasheet's figures; a lab's own profile wins."""
    from tankdaq.campaign.synthetic import SimulatedTest, simulated_decay, write_simulated_recording
    from tankdaq.ident.budget_inputs import DeviceProfile

    test = SimulatedTest(duration_s=6.0)
    t, angle, rate = simulated_decay(truth(), 10.0, test, np.random.default_rng(2))
    labels = ("catamaran", "roll", 1.0, 10.0)
    path = write_simulated_recording(
        tmp_path / "old.mcap", labels, t, angle, rate, test, {"product_code": "MTi-G"}
    )
    sources = set(tankdaq.identify(path, model="b1,b2,c1,c3").budget["source"])
    assert "angle accuracy (MTi-G (legacy))" in sources and "angle accuracy (MTi-G-710)" not in sources
    ours = DeviceProfile("our MTi-G", 0.1, 0.01, 5.0, 1e-4, "our calibration, 2026")
    table = tankdaq.identify(path, model="b1,b2,c1,c3", device=ours).budget
    row = table[(table["quantity"] == "B_eq/I at 5 deg") & (table["source"] == "angle accuracy (our MTi-G)")]
    assert row["u"].iloc[0] == 0.1


@pytest.mark.slow
def test_the_cli_takes_a_labs_angle_accuracy_and_refuses_a_bad_one(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from tankdaq.campaign.synthetic import SimulatedTest, write_simulated_campaign
    from tankdaq.cli import app

    (path,) = write_simulated_campaign(
        tmp_path, ["catamaran"], "roll", [1.0], [10.0], test=SimulatedTest(6.0)
    )
    args = ["identify", str(path), "--model", "b1,b2,c1,c3", "--angle-accuracy", "0.1", "--json"]
    done = CliRunner().invoke(app, args)
    assert done.exit_code == 0, done.output
    b_eq = next(b for b in json.loads(done.stdout)["budget"] if b["key"] == "b_eq_per_s@5")
    (row,) = [r for r in b_eq["rows"] if r["source"].startswith("angle accuracy")]
    assert row["u"] == 0.1 and "the lab's" in row["source"] and "--angle-accuracy 0.1" in row["note"]
    bad = CliRunner().invoke(app, ["identify", str(path), "--angle-accuracy", "0"])
    assert bad.exit_code == 2 and "roll/pitch accuracy in degrees RMS" in bad.output
    assert "Traceback" not in bad.output
