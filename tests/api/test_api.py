"""The public Python API (issue 23): tankdaq.read/identify/campaign/diagnose/simulate.

Real files throughout: ``simulate`` writes recordings that the official ``mcap`` reader reads back, the
CLI runs in-process on the same files, and the API must give the CLI's numbers exactly.
"""

from __future__ import annotations

import html
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

import tankdaq
from tankdaq.cli import app
from tankdaq.errors import InputError
from tankdaq.store.reader import read_recording

runner = CliRunner()


def timeless(document: dict) -> dict:
    """The document without the fits' wall times, the one value two runs never share."""
    for fit in [document, *document.get("groups", [])]:
        fit.pop("elapsed_s", None)
    return document


def cli_json(*args: object) -> dict:
    result = runner.invoke(app, [*map(str, args), "--json"])
    assert result.exit_code == 0, result.output
    return timeless(json.loads(result.stdout))


def api_json(result: tankdaq.Identification) -> dict:
    return timeless(json.loads(result.to_json()))


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> list[tankdaq.Recording]:
    return tankdaq.simulate(tmp_path_factory.mktemp("sim"), seed=5, runs=2, decay_s=15.0)


@pytest.mark.slow
def test_import_is_light_and_every_public_name_resolves() -> None:
    probe = (
        "import sys, json, tankdaq\n"
        "loaded = {m.split('.')[0] for m in sys.modules}\n"
        "heavy = sorted({'pandas', 'scipy', 'matplotlib', 'numba', 'mcap'} & loaded)\n"
        "names = [n for n in tankdaq.__all__ if getattr(tankdaq, n) is None]\n"
        "hidden = sorted(set(tankdaq.__all__) - set(dir(tankdaq)))\n"
        "from tankdaq.diagnose.workflow import Diagnoser\n"  # the room named like the function, loaded
        "room = tankdaq.diagnose.__module__\n"
        "print(json.dumps({'heavy': heavy, 'missing': names, 'dir': hidden, 'diagnose': room}))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout)
    assert found == {"heavy": [], "missing": [], "dir": [], "diagnose": "tankdaq.api.diagnosis"}
    with pytest.raises(AttributeError, match="no attribute 'ident_internal'"):
        _ = tankdaq.ident_internal


def test_simulate_writes_recordings_the_mcap_reader_reads(simulated: list[tankdaq.Recording]) -> None:
    assert len(simulated) == 2 and len({rec.path for rec in simulated}) == 2
    for rec in simulated:
        with rec.path.open("rb") as stream:
            events = [
                json.loads(message.data)
                for _, channel, message in make_reader(stream).iter_messages()
                if channel.topic == "/events"
            ]
        (release,) = [event for event in events if event["kind"] == "release"]
        assert rec.meta["release_device_time_s"] == [release["t_s"]]
        assert len(rec.decays) == 1 and 6.0 < abs(rec.decays[0].initial_angle_deg) < 10.0
        assert rec.meta["hull"] == "swath" and rec.meta["draft"] == 1.0 and rec.meta["axis"] == "roll"


def test_read_gives_samples_in_degrees_with_units_in_the_names(simulated: list[tankdaq.Recording]) -> None:
    rec = tankdaq.read(simulated[0].path)
    stored = read_recording(rec.path).samples
    samples = rec.samples
    assert isinstance(samples, pd.DataFrame) and len(samples) == stored.size
    np.testing.assert_array_equal(samples["roll_deg"], np.degrees(stored["roll"]))
    np.testing.assert_array_equal(samples["p_deg_s"], np.degrees(stored["p"]))
    np.testing.assert_array_equal(samples["az_m_s2"], stored["az"])
    np.testing.assert_array_equal(samples["device_time_s"], stored["t"])
    release = rec.meta["release_device_time_s"][0]
    np.testing.assert_array_equal(samples["time_s"], stored["t"] - release)
    assert (
        rec.units["roll_deg"] == "deg" and rec.units["p_deg_s"] == "deg/s" and set(rec.units) == set(samples)
    )
    decay = rec.decays[0].samples
    assert decay["time_s"].iloc[0] >= 0.0 and decay["time_s"].iloc[0] < 0.01
    assert decay["roll_deg"].iloc[0] == pytest.approx(rec.decays[0].initial_angle_deg)
    assert "<table" in rec._repr_html_() and rec.path.name in rec._repr_html_()


@pytest.mark.slow
def test_identify_gives_the_cli_numbers_with_b44_hat(simulated: list[tankdaq.Recording]) -> None:
    rec = simulated[0]
    result = tankdaq.identify(rec, hull="swath")
    assert api_json(result) == cli_json("identify", rec.path, "--hull", "swath")
    document = result.document
    table = result.coefficients.set_index("term")
    assert list(table.index) == document["model"]["terms"]
    for term, entry in document["coefficients"].items():
        assert table.loc[term, "value"] == entry["value"]
        assert (table.loc[term, "ci95_low"], table.loc[term, "ci95_high"]) == tuple(entry["ci95"])
        assert table.loc[term, "unit"] == entry["unit"]
    derived = result.derived
    assert list(derived["b44_hat"]) == [row["b44_hat"] for row in document["b_eq"]]
    assert np.all(np.isfinite(derived["b44_hat"])) and np.all(derived["b44_hat"] > 0)
    assert list(derived["b_eq_per_s"]) == [row["value_per_s"] for row in document["b_eq"]]
    assert result.notices and "chosen by data" in result.notices[-1]


def test_identify_reads_a_csv_pandas_wrote_as_the_cli_does(
    simulated: list[tankdaq.Recording], tmp_path: Path
) -> None:
    path = tmp_path / "decay.csv"
    simulated[1].decays[0].samples[["time_s", "roll_deg", "p_deg_s"]].to_csv(path, index=False)
    reading = tankdaq.Reading(angle_col="roll_deg", rate_col="p_deg_s")
    result = tankdaq.identify(path, "b1,b2,c1,c3", reading=reading)
    expected = cli_json(
        "identify", path, "--model", "b1,b2,c1,c3", "--angle-col", "roll_deg", "--rate-col", "p_deg_s"
    )
    assert api_json(result) == expected
    assert list(result.coefficients["term"]) == ["b1", "b2", "c1", "c3"]
    figure = result.plot()
    assert figure.axes[-1].get_xlabel() == "time since release (s)"
    assert "roll angle (deg)" in figure.axes[0].get_ylabel()
    shown = result._repr_html_()
    assert all(f"<td>{term}</td>" in shown for term in ("b1", "b2", "c1", "c3"))


def test_bad_input_is_one_line(simulated: list[tankdaq.Recording], tmp_path: Path) -> None:
    cases = [
        (lambda: tankdaq.identify(tmp_path / "missing.mcap"), "missing.mcap"),
        (lambda: tankdaq.identify(simulated[0], model="b9,c1"), "b9"),
        (lambda: tankdaq.identify([]), "sources: give a path, a Recording"),
        (lambda: tankdaq.identify(simulated[0], draft="3T"), "outside"),
        (lambda: tankdaq.read(tmp_path / "notes.md"), "unknown file type"),
        (lambda: tankdaq.simulate(tmp_path, axis="yaw"), "roll or pitch"),
        (lambda: tankdaq.Reading(axis="heave"), "roll or pitch"),
    ]
    for call, said in cases:
        with pytest.raises(InputError) as caught:
            call()
        assert said in str(caught.value) and "\n" not in str(caught.value)
        assert caught.value.exit_code == 2


@pytest.mark.slow
def test_campaign_and_diagnose_give_their_commands_results(
    simulated: list[tankdaq.Recording], tmp_path: Path
) -> None:
    folder = simulated[0].path.parent
    result = tankdaq.campaign(folder, "b1,b2,c1")
    (row,) = result.table.to_dict("records")
    assert row["runs"] == 2 and row["hull"] == "swath" and row["error"] == ""
    done = runner.invoke(
        app, ["campaign", str(folder), "--model", "b1,b2,c1", "--jobs", "1", "--report", str(tmp_path)]
    )
    assert done.exit_code == 0, done.output
    (written,) = pd.read_csv(tmp_path / "campaign.csv").to_dict("records")
    for key in ("b1", "b2", "c1", "b1_std", "natural_period_s", "b_eq_per_s"):
        assert row[key] == written[key]
    diagnosis = tankdaq.diagnose(simulated[0], max_steps=1)
    command = cli_json("diagnose", simulated[0].path, "--max-steps", "1")
    assert command.pop("truncated") is False and command.pop("truncated_files") == []
    assert {k: v for k, v in diagnosis.document.items() if k != "elapsed_s"} == command
    assert any(line.startswith("baseline b1,c1: RMS") for line in diagnosis.story)


@pytest.mark.slow
def test_conditions_are_fitted_apart_as_the_cli_fits_them(
    simulated: list[tankdaq.Recording], tmp_path: Path
) -> None:
    (deeper,) = tankdaq.simulate(tmp_path, draft="1.1T", seed=6, decay_s=15.0)
    assert deeper.meta["draft"] == pytest.approx(1.1)
    sources = [simulated[0].path, deeper.path]
    result = tankdaq.identify(sources, "b1,b2,c1")
    assert api_json(result) == cli_json("identify", *sources, "--model", "b1,b2,c1")
    assert [fit.label for fit in result.fits] == ["swath T roll", "swath 1.1T roll"]
    table = result.coefficients
    assert list(table["condition"]) == ["swath T roll"] * 3 + ["swath 1.1T roll"] * 3
    assert list(table["value"]) == [
        group["coefficients"][term]["value"]
        for group in result.document["groups"]
        for term in ("b1", "b2", "c1")
    ]
    assert set(result.derived["condition"]) == {"swath T roll", "swath 1.1T roll"}
    assert any(line.startswith("2 conditions, one fit each") for line in result.notices)


def test_warnings_go_wherever_the_result_is_shown(tmp_path: Path) -> None:
    """A noise-free decay leaves residuals far from white: the fit warns, and every view of it says so."""
    from tankdaq.physics.decay import simulate_decay

    t = np.arange(0.0, 40.0, 0.02)
    angle, rate = simulate_decay({"b1": 0.05, "c1": 1.6}, t, np.radians(8.0))
    path = tmp_path / "clean.csv"
    pd.DataFrame({"time_s": t, "angle_deg": np.degrees(angle), "rate_deg_s": np.degrees(rate)}).to_csv(
        path, index=False
    )
    result = tankdaq.identify(path, "b1,c1")
    assert result.warnings and result.warnings == result.document["warnings"]
    assert result.coefficients.attrs["warnings"] == result.warnings == result.derived.attrs["warnings"]
    assert f"({len(result.warnings)} warnings: result.warnings)" in result.plot().axes[0].get_title()
    shown = result._repr_html_()
    assert all(f"warning: {line}" in shown for line in map(html.escape, result.warnings))
    assert all(f"warning: {line}" in result.text() for line in result.warnings)


def test_an_exported_csv_reads_back_as_the_recording(
    simulated: list[tankdaq.Recording], tmp_path: Path
) -> None:
    rec = simulated[0]
    back = tankdaq.read(rec.to_csv(tmp_path))
    assert back.meta["format"] == "CSV" and back.units == rec.units
    columns = list(rec.samples)
    same = {"check_exact": True, "check_dtype": False}  # the CSV reader gives floats; the values are equal
    pd.testing.assert_frame_equal(back.samples[columns], rec.samples, **same)
    pd.testing.assert_frame_equal(back.decays[0].samples[columns], rec.decays[0].samples, **same)
    with pytest.raises(InputError, match="CSV file already"):
        back.to_csv(tmp_path)


KVLCC2 = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)


@pytest.mark.skipif(not KVLCC2.is_file(), reason=f"the KVLCC2 roll decay is not at {KVLCC2}")
def test_a_foreign_csv_in_radians_reads_in_degrees() -> None:
    rec = tankdaq.read(KVLCC2, time_col="time", angle_col="phi", rate_col=None)
    raw = pd.read_csv(KVLCC2)
    np.testing.assert_allclose(rec.samples["roll_deg"], np.degrees(raw["phi"]), rtol=1e-12)
    assert rec.units["roll_deg"] == "deg" and rec.units["theta"] == "as read"
    assert any("angle unit: rad" in line for line in rec.notices)
    assert len(rec.decays) == 1 and rec.decays[0].samples["time_s"].iloc[0] == 0.0
    assert abs(rec.decays[0].initial_angle_deg) > 5.0


def test_a_recording_stopped_before_a_release_reads_without_decays(tmp_path: Path) -> None:
    """Its samples are not lost to a missing release: read gives them and says why there is no decay;
    identify refuses it in one line."""
    from tankdaq.samples import empty_samples
    from tankdaq.store.writer import RecordingWriter

    samples = empty_samples(200)
    samples["t"] = 100.0 + np.arange(200) / 100.0
    samples["roll"] = np.radians(2.0)
    samples["p"] = 0.0
    with RecordingWriter(tmp_path / "held.mcap", {"axis": "roll"}, {}) as writer:
        writer.write_samples(samples)
    rec = tankdaq.read(writer.path)
    assert rec.decays == [] and rec.meta["release_device_time_s"] == []
    assert any("no release recorded" in line for line in rec.notices)
    np.testing.assert_array_equal(rec.samples["time_s"], samples["t"] - 100.0)
    np.testing.assert_array_equal(rec.samples["roll_deg"], np.full(200, 2.0))
    with pytest.raises(InputError, match="hold no release"):
        tankdaq.identify(rec)
