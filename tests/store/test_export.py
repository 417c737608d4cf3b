"""tankdaq export: files pandas, Excel, MATLAB, h5py and pyarrow open with defaults, holding the
recording exactly; identify reads the CSV back exactly (also an export written before the sidecar)."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.io import loadmat
from typer.testing import CliRunner

from tankdaq.campaign.groups import csv_labels
from tankdaq.cli import app
from tankdaq.samples import SAMPLE_DTYPE
from tankdaq.store.export import ExportTable
from tankdaq.store.export_layout import column_name
from tankdaq.store.export_writers import write_csv
from tankdaq.store.reader import read_recording
from tankdaq.store.writer import RecordingWriter

runner = CliRunner()
#: The device clock of a real MTi session is hours in: times since release are differences of large numbers.
DEVICE_T0_S = 22568.0
RELEASES_S = (DEVICE_T0_S + 2.0, DEVICE_T0_S + 9.0)


@pytest.fixture(scope="module")
def two_decays(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A pitch recording on a device clock hours in, released twice, with a yaw gap (NaN) and a row
    without a pitch angle (not exportable: dropped)."""
    n = 1500
    rng = np.random.default_rng(3)
    samples = np.zeros(n, dtype=SAMPLE_DTYPE)
    samples["ticks"] = np.round(DEVICE_T0_S * 1e4).astype(np.int64) + 100 * np.arange(n)
    samples["t"] = samples["ticks"] / 1e4
    samples["counter"] = np.arange(n) % 65536
    for field in ("roll", "pitch", "yaw", "p", "q", "r", "ax", "ay", "az"):
        samples[field] = rng.normal(0.0, 0.1, n)
    samples["yaw"][100:110] = np.nan
    samples["pitch"][700] = np.nan
    path = tmp_path_factory.mktemp("two") / "trimaran_T_pitch_6deg.mcap"
    meta = {"axis": "pitch", "hull": "trimaran", "draft": "1.1T", "angle_nominal_deg": "6", "baud": "115200"}
    with RecordingWriter(path, meta, {}) as writer:
        writer.write_samples(samples)
        for release in RELEASES_S:
            writer.write_event("release", "by hand", t_s=release)
    return path


def export(*args: object) -> list[Path]:
    result = runner.invoke(app, ["export", *map(str, args)])
    assert result.exit_code == 0, result.output
    return [Path(line) for line in result.stdout.splitlines()]


def identify_json(*args: object) -> dict:
    result = runner.invoke(app, ["identify", *map(str, args), "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.fixture(scope="module")
def direct(recording: Path) -> dict:
    """``tankdaq identify --json`` of the recording itself (fitted once for the tests comparing with it)."""
    return identify_json(recording)


def usable(path: Path) -> np.ndarray:
    """The samples an export holds: finite time, decay angle and rate."""
    samples = read_recording(path).samples
    keep = np.isfinite(samples["t"]) & np.isfinite(samples["pitch"]) & np.isfinite(samples["q"])
    return samples[keep]


def assert_exact(read: dict[str, np.ndarray], samples: np.ndarray, release_s: float) -> None:
    """Every sample field is in the file bit for bit; time since release is t - release, the device
    clock is there unchanged."""
    np.testing.assert_array_equal(read["time_s"], samples["t"] - release_s, strict=True)
    np.testing.assert_array_equal(read["device_time_s"], samples["t"], strict=True)
    for field in SAMPLE_DTYPE.names or ():
        if field != "t":
            np.testing.assert_array_equal(np.asarray(read[column_name(field)]), samples[field])


# ---------------------------------------------------------------------------------------------------
# CSV: pandas, Excel, MATLAB without options; identify and campaign read it back exactly
# ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("frame", ["device", "release"])
@pytest.mark.slow
def test_identify_of_the_export_equals_identify_of_the_recording(recording, direct, tmp_path, frame):
    written = export(recording, "--out", tmp_path, "--frame", frame)
    assert written == [tmp_path / f"{recording.stem}.csv", tmp_path / f"{recording.stem}.json"]
    again = identify_json(written[0])
    for term, c in direct["coefficients"].items():
        assert again["coefficients"][term]["value"] == pytest.approx(c["value"], rel=1e-9, abs=0)
    assert again["runs"][0]["samples"] == direct["runs"][0]["samples"]
    assert again["runs"][0]["cut"]["end_s"] == direct["runs"][0]["cut"]["end_s"]


def test_plain_read_csv_gives_the_recording_exactly(two_decays, tmp_path):
    frame = pd.read_csv(export(two_decays, "--out", tmp_path)[0])
    samples = usable(two_decays)
    assert frame["ticks"].dtype == np.int64 and frame["pitch_rad"].dtype == np.float64
    assert frame["yaw_rad"].isna().sum() == 10  # the gap is empty cells, read as missing
    assert_exact({name: frame[name].to_numpy() for name in frame.columns}, samples, RELEASES_S[0])


@settings(max_examples=40, deadline=None)
@given(
    values=arrays(np.float64, st.integers(1, 40), elements=st.floats(width=64)),
    ticks=st.integers(-(2**63), 2**63 - 1),
)
def test_any_float_and_integer_reads_back_bit_for_bit(tmp_path_factory, values, ticks):
    """Subnormals, huge values, -0.0, infinities and NaN (an empty cell) through plain pd.read_csv."""
    path = tmp_path_factory.mktemp("any") / "x.csv"
    columns = {"x_rad": values, "ticks": np.full(values.size, ticks, dtype=np.int64)}
    write_csv(
        ExportTable("x", columns, {"x_rad": "rad", "ticks": "0.1 ms"}, {"format": "tankdaq export"}), path
    )
    read = pd.read_csv(path)
    got = read["x_rad"].to_numpy(dtype=np.float64)
    nan = np.isnan(values)
    np.testing.assert_array_equal(np.isnan(got), nan)
    np.testing.assert_array_equal(got[~nan].view(np.uint64), values[~nan].view(np.uint64))
    np.testing.assert_array_equal(read["ticks"].to_numpy(), columns["ticks"], strict=True)


def test_csv_is_one_ascii_header_row_then_numbers(two_decays, tmp_path):
    """What Excel and MATLAB readtable need to open it with defaults: no comment block, no units row."""
    path = export(two_decays, "--out", tmp_path)[0]
    path.read_bytes().decode("ascii")
    rows = list(csv.reader(path.open(newline="")))
    header, body = rows[0], rows[1:]
    assert header[:5] == ["time_s", "device_time_s", "pitch_rad", "q_rad_s", "ticks"]
    assert all(name.isidentifier() for name in header)  # MATLAB keeps them as variable names
    assert {len(row) for row in body} == {len(header)}
    for row in body:
        [float(cell) for cell in row if cell != ""]


def test_sidecar_holds_typed_metadata_and_labels_the_campaign(two_decays, tmp_path):
    csv_path, sidecar = export(two_decays, "--out", tmp_path)
    meta = json.loads(sidecar.read_text())
    assert meta["angle_nominal_deg"] == 6 and meta["baud"] == 115200 and meta["draft"] == "1.1T"
    assert meta["release_t_s"] == [0.0, RELEASES_S[1] - RELEASES_S[0]] and meta["frame"] == "release"
    assert meta["time_origin_s"] == RELEASES_S[0] and meta["dropped_rows"] == 1
    assert meta["complete_file"] is True and meta["units"]["q_rad_s"] == "rad/s"
    labels = csv_labels(csv_path)
    assert (labels["hull"], labels["axis"], labels["angle_deg"]) == ("trimaran", "pitch", 6.0)


def test_exported_csv_is_cut_at_its_releases_on_its_own_axis(two_decays, tmp_path):
    from tankdaq.store.csv_import import read_csv_file

    runs = read_csv_file(export(two_decays, "--out", tmp_path)[0])
    samples = usable(two_decays)
    first = samples["t"] < RELEASES_S[1]
    assert [run.name for run in runs] == [f"{two_decays.stem}#1", f"{two_decays.stem}#2"]
    assert all(run.axis == "pitch" for run in runs)
    np.testing.assert_array_equal(runs[1].angle, samples["pitch"][~first])
    assert runs[0].t[0] == 0.0 and runs[1].t[0] == samples["t"][~first][0] - RELEASES_S[0]


def old_style_export(recording: Path, path: Path) -> Path:
    """A CSV as ``tankdaq export`` wrote it before the sidecar: comment block, header, units row."""
    samples = usable_roll(recording)
    release = 0.5
    meta = {"hull": "swath", "axis": "roll", "frame": "release", "release_t_s": [0.0]}
    lines = ["# tankdaq export of x.mcap", *(f"# {k} = {json.dumps(v)}" for k, v in meta.items())]
    lines += ["time_s,angle_rad,rate_rad_s", "s,rad,rad/s"]
    t = (samples["t"] - release).tolist()
    rows = zip(t, samples["roll"].tolist(), samples["p"].tolist(), strict=True)
    lines += [f"{t!r},{a!r},{r!r}" for t, a, r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def usable_roll(path: Path) -> np.ndarray:
    samples = read_recording(path).samples
    return samples[np.isfinite(samples["roll"]) & np.isfinite(samples["p"])]


@pytest.mark.slow
def test_an_export_written_before_the_sidecar_is_still_read_exactly(recording, direct, tmp_path):
    old = identify_json(old_style_export(recording, tmp_path / "old.csv"))
    for term, c in direct["coefficients"].items():
        assert old["coefficients"][term]["value"] == pytest.approx(c["value"], rel=1e-9, abs=0)
    assert old["runs"][0]["samples"] == direct["runs"][0]["samples"]


@pytest.mark.parametrize(
    ("key", "value", "says"),
    [("release_t_s", [3, 1], "release_t_s"), ("release_t_s", "soon", "release_t_s"), ("axis", 7, "axis 7")],
)
@pytest.mark.slow
def test_a_malformed_sidecar_is_one_line(recording, tmp_path, key, value, says):
    csv_path, sidecar = export(recording, "--out", tmp_path)
    sidecar.write_text(json.dumps({**json.loads(sidecar.read_text()), key: value}))
    result = runner.invoke(app, ["identify", str(csv_path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    (line,) = result.stderr.strip().splitlines()
    assert says in line and str(csv_path) in line


# ---------------------------------------------------------------------------------------------------
# HDF5, Parquet, .mat
# ---------------------------------------------------------------------------------------------------


def test_h5_is_one_file_per_decay_with_units_and_typed_attributes(two_decays, tmp_path):
    written = export(two_decays, "--format", "h5", "--out", tmp_path)
    assert [p.name for p in written] == [f"{two_decays.stem}_decay{k}.h5" for k in (1, 2)]
    samples = usable(two_decays)
    parts = np.split(samples, [int(np.searchsorted(samples["t"], RELEASES_S[1]))])
    for k, (path, part, release) in enumerate(zip(written, parts, RELEASES_S, strict=True), start=1):
        with h5py.File(path, "r") as h5:
            assert_exact({name: h5[name][()] for name in h5}, part, release)
            assert h5["q_rad_s"].attrs["unit"] == "rad/s" and h5["time_s"].attrs["unit"] == "s"
            attrs = dict(h5.attrs)
        assert attrs["decay"] == k and attrs["decays"] == 2 and attrs["axis"] == "pitch"
        assert attrs["angle_nominal_deg"] == 6 and attrs["baud"] == 115200 and attrs["draft"] == "1.1T"
        np.testing.assert_array_equal(attrs["release_t_s"], [0.0])
        assert attrs["time_origin_s"] == release and bool(attrs["complete_file"]) is True
    assert sum(part.size for part in parts) == samples.size  # every exported row is in one of the files


def test_parquet_round_trip_is_exact_with_units_and_metadata(two_decays, tmp_path):
    import pyarrow.parquet as pq

    (path,) = export(two_decays, "--format", "parquet", "--out", tmp_path)
    table = pq.read_table(path)
    read = {name: table[name].to_numpy() for name in table.column_names}
    assert_exact(read, usable(two_decays), RELEASES_S[0])
    assert table.schema.field("pitch_rad").metadata == {b"unit": b"rad"}
    meta = json.loads(table.schema.metadata[b"tankdaq"])
    assert meta["axis"] == "pitch" and meta["release_t_s"][0] == 0.0 and meta["angle_nominal_deg"] == 6


def test_parquet_without_pyarrow_says_how_to_get_it(recording, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # what `import pyarrow` meets where it is absent
    result = runner.invoke(app, ["export", str(recording), "--format", "parquet", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    (line,) = result.stderr.strip().splitlines()
    assert "pip install 'tankdaq[parquet]' (from a clone: pip install '.[parquet]')" in line
    assert not list(tmp_path.iterdir())


def test_mat_holds_a_struct_with_columns_units_and_metadata(recording, tmp_path):
    (path,) = export(recording, "--format", "mat", "--out", tmp_path)
    data = loadmat(path, simplify_cells=True)["tankdaq"]
    samples = read_recording(recording).samples
    np.testing.assert_array_equal(data["time_s"], samples["t"] - 0.5)
    np.testing.assert_array_equal(data["device_time_s"], samples["t"])
    np.testing.assert_array_equal(data["roll_rad"], samples["roll"])
    assert data["units"]["p_rad_s"] == "rad/s" and data["meta"]["hull"] == "swath"


def test_a_recording_without_a_release_keeps_the_device_clock_and_says_so(tmp_path):
    samples = np.zeros(100, dtype=SAMPLE_DTYPE)
    samples["t"] = DEVICE_T0_S + np.arange(100) / 100
    samples["roll"], samples["p"] = np.linspace(0.1, -0.1, 100), -0.2
    path = tmp_path / "trimaran_T_roll_6deg.mcap"
    with RecordingWriter(path, {"axis": "roll", "hull": "trimaran"}, {}) as writer:
        writer.write_samples(samples)
    result = runner.invoke(app, ["export", str(path), "--format", "h5"])
    assert result.exit_code == 0, result.output
    assert "no release recorded" in result.stderr and "--frame device" in result.stderr
    with h5py.File(tmp_path / "trimaran_T_roll_6deg.h5", "r") as h5:
        np.testing.assert_array_equal(h5["time_s"][()], samples["t"])
        assert h5.attrs["frame"] == "device" and "device_time_s" not in h5


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--format", "xls"], "format 'xls'"), (["--frame", "gps"], "frame 'gps'")],
)
def test_bad_options_are_one_line(recording, args, message):
    result = runner.invoke(app, ["export", str(recording), *args])
    assert result.exit_code == 2 and message in result.output and "Traceback" not in result.output
    assert "csv, h5, parquet, mat" in result.output or "release or device" in result.output


def test_help_lists_every_format():
    result = runner.invoke(app, ["export", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for name in ("csv", "h5", "parquet", "mat", "release", "device"):
        assert name in result.output
    assert "tankdaq[parquet]" in result.output


def test_campaign_reads_the_exported_csv_as_the_recording(recording, tmp_path):
    from tankdaq.campaign.groups import read_campaign_runs

    (direct,), (again,) = (
        read_campaign_runs(recording),
        read_campaign_runs(export(recording, "--out", tmp_path)[0]),
    )
    for key in ("hull", "draft", "axis", "angle_deg"):
        assert again.meta[key] == direct.meta[key]
    np.testing.assert_array_equal(again.angle, direct.angle)
    np.testing.assert_array_equal(again.rate, direct.rate)
    np.testing.assert_array_equal(again.t - again.t[0], direct.t - direct.t[0])


def test_a_json_beside_that_is_not_an_export_is_never_overwritten(recording, tmp_path):
    labels = tmp_path / f"{recording.stem}.json"
    labels.write_text('{"hull": "swath", "axis": "roll", "angle_deg": 8}')
    result = runner.invoke(app, ["export", str(recording), "--out", str(tmp_path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    (line,) = result.stderr.strip().splitlines()
    assert str(labels) in line and "another folder" in line
    assert labels.read_text() == '{"hull": "swath", "axis": "roll", "angle_deg": 8}'
    assert not (tmp_path / f"{recording.stem}.csv").exists()
    first = {path: path.read_bytes() for path in export(recording, "--out", tmp_path / "again")}
    again = runner.invoke(app, ["export", str(recording), "--out", str(tmp_path / "again")])
    assert again.exit_code == 2 and "never writes over a file" in again.stderr  # not even an earlier export
    assert {path: path.read_bytes() for path in first} == first
