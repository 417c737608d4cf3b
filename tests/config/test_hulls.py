"""Hull files: lookup order, the template, a lab's own hull without coefficients."""

from __future__ import annotations

import csv as csv_module
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from support.held_tilt import write_held_tilt_csv
from tankdaq.cli import app
from tankdaq.config.hulls import hull_scenario, load_hull, user_hulls_dir

runner = CliRunner()

MY_HULL = """
name = "mymodel"
description = "a lab's own model"
[dimensions]
displacement_kg = 40.0
[axes.roll]
gm_m = 0.1
radius_of_gyration_m = 0.15
"""


@pytest.fixture
def user_folder(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "hulls"
    monkeypatch.setenv("TANKDAQ_HULLS_DIR", str(folder))
    return folder


def test_xdg_rule(monkeypatch, tmp_path):
    monkeypatch.delenv("TANKDAQ_HULLS_DIR", raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    assert user_hulls_dir() == tmp_path / "tankdaq" / "hulls"
    monkeypatch.setenv("XDG_CONFIG_HOME", "relative/ignored")
    assert user_hulls_dir() == Path.home() / ".config" / "tankdaq" / "hulls"


@pytest.mark.slow
def test_new_writes_a_template_that_loads_and_the_list_says_where_each_came_from(user_folder):
    result = runner.invoke(app, ["hulls", "new", "mymodel"])
    assert result.exit_code == 0, result.output
    *template, last = result.stdout.splitlines()
    path = Path(last)
    assert path == user_folder / "mymodel.toml" and path.read_text().count("#") > 10
    assert template == path.read_text().splitlines()  # the template it wrote is printed, then its path
    hull = load_hull("mymodel")
    assert hull.origin == "user" and hull.simulation == {} and hull.particulars("roll").gm_m == 0.05
    again = runner.invoke(app, ["hulls", "new", "mymodel"])
    assert again.exit_code == 2 and "already exists" in again.output
    listing = runner.invoke(app, ["hulls"]).stdout
    assert f"from user: {path}" in listing and "from shipped:" in listing


def test_lookup_order_path_then_user_then_shipped(user_folder, tmp_path):
    user_folder.mkdir()
    (user_folder / "swath.toml").write_text(MY_HULL.replace("mymodel", "swath"))
    assert load_hull("swath").origin == "user" and load_hull("swath").simulation == {}
    assert "hides the shipped" in runner.invoke(app, ["hulls"]).stdout
    own = tmp_path / "elsewhere.toml"
    own.write_text(MY_HULL)
    hull = load_hull(str(own))
    assert (hull.origin, hull.name, hull.dry_inertia_kg_m2("roll")) == ("path", "mymodel", pytest.approx(0.9))
    (user_folder / "swath.toml").unlink()
    assert load_hull("swath").origin == "shipped" and "roll" in load_hull("swath").simulation


def test_record_needs_a_hull():
    result = runner.invoke(app, ["record", "--port", "sim", "--draft", "T", "--angle", "8"])
    assert result.exit_code == 2 and "--hull" in result.output


@pytest.mark.slow
def test_a_hull_without_coefficients_cannot_be_simulated_but_identifies(tmp_path, user_folder):
    own = tmp_path / "mymodel.toml"
    own.write_text(MY_HULL)
    out = tmp_path / "rec"
    result = runner.invoke(
        app,
        ["record", "--port", "sim", "--draft", "T", "--angle", "8", "--hull", str(own), "--out", str(out),
         "--viewer", "none", "--seed", "0"],
    )  # fmt: skip
    assert result.exit_code == 2 and "simulator needs" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not out.exists()  # refused before anything opened
    csv = write_held_tilt_csv(tmp_path / "a.csv")
    ident = runner.invoke(app, ["identify", str(csv), "--model", "b1,b2,c1", "--hull", str(own), "--json"])
    assert ident.exit_code == 0, ident.output
    dimensional = json.loads(ident.stdout)["dimensional"]
    assert dimensional["gm_m"] == 0.1 and dimensional["displacement_kg"] == 40.0
    assert dimensional["added_inertia_fraction"] is not None  # from the radius of gyration


@pytest.mark.slow
def test_campaign_uses_the_user_hulls_gm(tmp_path, user_folder):
    user_folder.mkdir()
    (user_folder / "mymodel.toml").write_text(MY_HULL)
    csv = write_held_tilt_csv(tmp_path / "mymodel_T_roll_8deg_run01.csv")
    report = tmp_path / "report"
    result = runner.invoke(app, ["campaign", str(csv), "--report", str(report)])
    assert result.exit_code == 0, result.output
    with (report / "campaign.csv").open(newline="") as fh:  # quoted cells (a warning) hold commas
        (fields,) = csv_module.DictReader(fh)
    assert float(fields["gm_m"]) == 0.1 and float(fields["total_inertia_kg_m2"]) > 0
    assert "free decay" in fields["cuts"]


@pytest.mark.slow
def test_a_hull_without_coefficients_records_from_a_real_port(tmp_path, record_settings):
    """The lab's own hull on a real serial port (the simulated MTi-G's pty, opened by path like hardware):
    the recording is labelled with it, and its dimensions travel in the file."""
    from tankdaq.acquire.daemon import RecordDaemon
    from tankdaq.device.simulator import SimulatedMTi
    from tankdaq.store.reader import read_recording

    own = tmp_path / "mymodel.toml"
    own.write_text(MY_HULL)
    scenario = hull_scenario(hull="swath", draft=1.0, angle_deg=8.0, runs=2, seed=5)
    with SimulatedMTi(scenario, speed=8.0, seed=5) as sim:
        settings = record_settings(port=sim.link, hull=str(own), runs=1)
        (outcome,) = RecordDaemon(settings).run()
    assert outcome.path is not None and outcome.path.name.startswith("mymodel_T_roll_8deg_")
    metadata = read_recording(outcome.path).metadata
    assert metadata["hull"] == "mymodel" and float(metadata["hull_displacement_kg"]) == 40.0
