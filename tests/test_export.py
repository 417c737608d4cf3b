"""tankdaq export: CSV read back exactly by identify, .mat via scipy, both time frames."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.ident.campaign import SimulatedTest, write_simulated_campaign
from tankdaq.store.reader import read_recording

runner = CliRunner()


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("rec")
    (path,) = write_simulated_campaign(
        folder, ["swath"], "roll", [1.0], [8.0], "mcap", test=SimulatedTest(duration_s=20.0)
    )
    return path


def identify_json(*args: object) -> dict:
    result = runner.invoke(app, ["identify", *map(str, args), "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.mark.parametrize("frame", ["device", "release"])
def test_identify_of_the_export_equals_identify_of_the_recording(recording, tmp_path, frame):
    result = runner.invoke(app, ["export", str(recording), "--out", str(tmp_path), "--frame", frame])
    assert result.exit_code == 0, result.output
    exported = Path(result.stdout.strip())
    assert exported == tmp_path / f"{recording.stem}.csv"
    direct, again = identify_json(recording), identify_json(exported)
    for term, c in direct["coefficients"].items():
        assert again["coefficients"][term]["value"] == pytest.approx(c["value"], rel=1e-9, abs=0)
    assert again["runs"][0]["samples"] == direct["runs"][0]["samples"]
    assert again["runs"][0]["cut"]["end_s"] == direct["runs"][0]["cut"]["end_s"]


def test_csv_has_units_row_metadata_and_every_channel(recording, tmp_path):
    runner.invoke(app, ["export", str(recording), "--out", str(tmp_path), "--frame", "release"])
    lines = (tmp_path / f"{recording.stem}.csv").read_text().splitlines()
    meta = {
        k.strip("# "): json.loads(v) for k, _, v in (line.partition(" = ") for line in lines if "=" in line)
    }
    assert meta["hull"] == "swath" and meta["frame"] == "release" and meta["release_t_s"] == [0.0]
    header, units = lines[len(meta) + 1].split(","), lines[len(meta) + 2].split(",")
    assert header[:3] == ["time_s", "angle_rad", "rate_rad_s"] and units[:3] == ["s", "rad", "rad/s"]
    assert {"pitch_rad", "yaw_rad", "q_rad_s", "r_rad_s", "ax_m_s2", "ay_m_s2", "az_m_s2"} <= set(header)
    samples = read_recording(recording).samples
    first = [float(x) for x in lines[len(meta) + 3].split(",")]
    assert first[1] == samples["roll"][0] and first[0] == samples["t"][0] - 0.5  # release at 0.5 s


def test_mat_holds_a_struct_with_columns_units_and_metadata(recording, tmp_path):
    result = runner.invoke(app, ["export", str(recording), "--format", "mat", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    data = loadmat(tmp_path / f"{recording.stem}.mat", simplify_cells=True)["tankdaq"]
    samples = read_recording(recording).samples
    np.testing.assert_array_equal(data["time_s"], samples["t"])
    np.testing.assert_array_equal(data["angle_rad"], samples["roll"])
    assert data["units"]["rate_rad_s"] == "rad/s" and data["meta"]["hull"] == "swath"


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--format", "xls"], "format 'xls'"), (["--frame", "gps"], "frame 'gps'")],
)
def test_bad_options_are_one_line(recording, args, message):
    result = runner.invoke(app, ["export", str(recording), *args])
    assert result.exit_code == 2 and message in result.output and "Traceback" not in result.output
