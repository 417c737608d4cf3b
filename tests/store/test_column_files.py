"""Decays from the column files a lab's archive and other tools hold: HDF5, MATLAB (v5 and v7.3) and
Parquet, written here by h5py, scipy.io and pyarrow themselves, read by ``tankdaq.read``, ``identify``
and ``campaign`` as a CSV is (the same columns, units decided by the data, every check), and never read
twice when two exports hold one recording's decays.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from scipy.io import savemat
from typer.testing import CliRunner

import tankdaq
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.cli import app
from tankdaq.errors import InputError
from tankdaq.store.export import export_recording

KVLCC2 = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)
FORMATS = ["h5", "mat", pytest.param("parquet", marks=pytest.mark.skipif(
    __import__("importlib").util.find_spec("pyarrow") is None, reason="the parquet extra is not installed"
))]  # fmt: skip


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two swath roll recordings at T (6 and 8 deg), one release each."""
    return write_simulated_campaign(
        tmp_path_factory.mktemp("rec"), ["swath"], "roll", [1.0], [6.0, 8.0], "mcap"
    )


def _export(recording: Path, file_format: str, out: Path) -> Path:
    return next(p for p in export_recording(recording, file_format, out) if p.suffix == f".{file_format}")


@pytest.mark.parametrize("file_format", FORMATS)
@pytest.mark.slow
def test_an_export_in_any_format_reads_back_as_its_recording(
    recordings: list[Path], tmp_path: Path, file_format: str
) -> None:
    exported = _export(recordings[0], file_format, tmp_path)
    original, back = tankdaq.read(recordings[0]), tankdaq.read(exported)
    assert len(back.decays) == 1 and back.meta["hull"] == "swath"
    columns = list(original.decays[0].samples)
    same = {"check_exact": True, "check_dtype": False}  # integers may come back as floats; values equal
    pd.testing.assert_frame_equal(back.decays[0].samples[columns], original.decays[0].samples, **same)
    fits = [tankdaq.identify(path, "b1,b3,c1,c3").coefficients for path in (recordings[0], exported)]
    pd.testing.assert_frame_equal(fits[1], fits[0])


def _kvlcc2_files(folder: Path) -> dict[str, tuple[Path, str, str]]:
    """The KVLCC2 decay as other tools write it: (file, time column, angle column)."""
    raw = pd.read_csv(KVLCC2)
    with h5py.File(folder / "kv.h5", "w") as h5:  # a group per run, units as attributes, and clutter
        run = h5.create_group("run21338")
        for name, unit in (("time", "s"), ("phi", "rad"), ("theta", "rad")):
            run.create_dataset(name, data=raw[name].to_numpy()).attrs["unit"] = unit
        h5["run21338/matrix"] = np.zeros((3, 3))
        h5["note"] = "towing tank, 2019"
    savemat(folder / "kv.mat", {"run": {"time": raw["time"].to_numpy(), "phi": raw["phi"].to_numpy()}})
    with h5py.File(folder / "kv73.mat", "w", userblock_size=512) as h5:  # MATLAB's own 7.3 layout: 1 x N
        h5["run/time"] = raw["time"].to_numpy()[None, :]
        h5["run/phi"] = raw["phi"].to_numpy()[None, :]
    with (folder / "kv73.mat").open("r+b") as fh:
        fh.write(
            b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".ljust(116)
            + bytes(8)
            + b"\x00\x02IM"
        )
    return {
        "h5": (folder / "kv.h5", "run21338/time", "run21338/phi"),
        "mat": (folder / "kv.mat", "run.time", "run.phi"),
        "mat73": (folder / "kv73.mat", "run.time", "run.phi"),
    }


@pytest.mark.skipif(not KVLCC2.is_file(), reason=f"the KVLCC2 roll decay is not at {KVLCC2}")
@pytest.mark.slow
def test_the_kvlcc2_decay_in_another_tools_hdf5_or_matlab_file_reads_as_its_csv(tmp_path: Path) -> None:
    csv = tankdaq.read(KVLCC2, time_col="time", angle_col="phi", rate_col=None)
    for kind, (path, time_col, angle_col) in _kvlcc2_files(tmp_path).items():
        rec = tankdaq.read(path, time_col=time_col, angle_col=angle_col, rate_col=None)
        assert len(rec.decays) == len(csv.decays) == 1, kind
        np.testing.assert_array_equal(rec.decays[0].run.angle, csv.decays[0].run.angle)
        np.testing.assert_array_equal(rec.decays[0].run.t, csv.decays[0].run.t)
        said_rad = any("angle unit: rad" in line for line in rec.notices)
        assert said_rad == (kind != "h5"), kind  # the h5 file says rad itself; the others are decided
    clutter = tankdaq.read(
        tmp_path / "kv.h5", time_col="run21338/time", angle_col="run21338/phi", rate_col=None
    )
    assert any("not read (not vectors of numbers): note, run21338/matrix" in line for line in clutter.notices)


def _h5(path: Path, angle: np.ndarray, unit: str | None, time: np.ndarray | None = None) -> Path:
    with h5py.File(path, "w") as h5:
        h5["t"] = np.arange(angle.size) * 0.01 if time is None else time
        h5["phi"] = angle
        if unit is not None:
            h5["phi"].attrs["unit"] = unit
    return path


def _decay(amplitude: float, n: int = 3000) -> np.ndarray:
    t = np.arange(n) * 0.01
    return amplitude * np.exp(-0.1 * t) * np.cos(2 * np.pi * t / 1.7)


def test_a_unit_attribute_breaks_a_tie_but_never_outvotes_the_data(tmp_path: Path) -> None:
    radians_said_deg = _h5(tmp_path / "a.h5", _decay(0.14), "degrees")  # 8 deg in rad; 0.14 deg no decay
    rec = tankdaq.read(radians_said_deg, time_col="t", angle_col="phi")
    assert rec.decays[0].initial_angle_deg == pytest.approx(np.degrees(0.14), rel=0.01)
    assert any("angle unit: rad" in line and "only rad is a decay" in line for line in rec.notices)

    tie = _decay(0.6)  # 0.6 deg, or 34 deg in rad: both a decay
    as_said = tankdaq.read(_h5(tmp_path / "b.h5", tie, "rad"), time_col="t", angle_col="phi")
    unsaid = tankdaq.read(_h5(tmp_path / "c.h5", tie, None), time_col="t", angle_col="phi")
    assert as_said.decays[0].initial_angle_deg == pytest.approx(np.degrees(0.6), rel=0.01)
    assert unsaid.decays[0].initial_angle_deg == pytest.approx(0.6, rel=0.01)
    for rec in (as_said, unsaid):  # the choice is said, and the doubt with it
        assert any("the other unit would be a decay too" in line for line in rec.notices)


@pytest.mark.slow
def test_two_exports_of_one_recording_are_read_once(recordings: list[Path], tmp_path: Path) -> None:
    first = _export(recordings[0], "h5", tmp_path / "h5").rename(tmp_path / "run_a.h5")
    again = _export(recordings[0], "mat", tmp_path / "mat").rename(tmp_path / "kept_for_matlab.mat")
    other = _export(recordings[1], "h5", tmp_path / "h5")
    found = tankdaq.identify([first, again, other], "b1,c1")
    assert sorted(run.name for run in found.fits[0].runs) == sorted([first.stem, other.stem])
    assert [line for line in found.notices if line.startswith("not read")] == [
        f"not read: {again} holds the same decays as {first} (exports of {recordings[0].name}) "
        "(the same decays, which would count twice)"
    ]
    both = tankdaq.identify([recordings[0], first], "b1,c1")
    assert [run.meta["file"] for run in both.fits[0].runs] == [str(recordings[0])]


@pytest.mark.slow
def test_a_folder_of_renamed_exports_is_a_campaign_labelled_by_their_own_metadata(
    recordings: list[Path], tmp_path: Path
) -> None:
    folder = tmp_path / "archive"
    folder.mkdir()
    _export(recordings[0], "h5", tmp_path).rename(folder / "21337.h5")
    _export(recordings[1], "mat", tmp_path).rename(folder / "21338.mat")
    result = tankdaq.campaign(folder, model="b1,c1")
    keys = sorted((g.hull, g.axis, g.draft, g.angle_deg) for g in (row.key for row in result.rows))
    assert keys == [("swath", "roll", 1.0, 6.0), ("swath", "roll", 1.0, 8.0)]


def _cli(*args: object) -> tuple[int, list[str]]:
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, [line for line in result.stderr.splitlines() if line.strip()]


@pytest.mark.skipif(
    __import__("importlib").util.find_spec("pyarrow") is None, reason="the parquet extra is not installed"
)
def test_timestamps_in_a_parquet_file_are_seconds_from_the_first_and_said(tmp_path: Path) -> None:
    t = np.arange(3000) * 0.01
    start = pd.Timestamp("2026-03-12 14:30:05")
    frame = pd.DataFrame({"stamp": start + pd.to_timedelta(t, unit="s"), "heel": _decay(np.radians(6.0))})
    frame.to_parquet(tmp_path / "logger.parquet")
    rec = tankdaq.read(tmp_path / "logger.parquet", time_col="stamp", angle_col="heel", rate_col=None)
    assert rec.decays[0].duration_s == pytest.approx(29.99, abs=0.011)
    assert rec.decays[0].initial_angle_deg == pytest.approx(6.0, rel=0.01)
    assert any(
        "column 'stamp': timestamps read as seconds from the first (2026-03-12" in n for n in rec.notices
    )


@pytest.mark.slow
def test_a_broken_or_foreign_column_file_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "cut.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(40))
    (tmp_path / "cut.mat").write_bytes(b"MATLAB 5.0 MAT-file, cut")
    angle = _decay(np.radians(8.0))
    _h5(tmp_path / "short.h5", angle[:2000], "rad", time=np.arange(3000) * 0.01)
    cases = {
        "cut.h5": "not an HDF5 file h5py can read",
        "cut.mat": "not a MATLAB file scipy can read",
        "short.h5": "the angle column 'phi' is not 3000 values long, as 't' is",
    }
    for name, said in cases.items():
        code, lines = _cli(
            "identify", tmp_path / name, "--time-col", "t", "--angle-col", "phi", "--catalogue", "none"
        )
        assert code == 2 and len(lines) == 1 and said in lines[0], (name, lines)
        assert "Traceback" not in lines[0]


@pytest.mark.slow
def test_a_csv_read_with_named_columns_gets_its_catalogue_row_and_fit(tmp_path: Path) -> None:
    """The catalogue makes the row of a file the command has just read with the user's columns, instead
    of failing to read it with the default ones (and saying ``index`` would catch up: it would not)."""
    (written,) = write_simulated_campaign(tmp_path / "csv", ["swath"], "roll", [1.0], [8.0], "csv")
    table = pd.read_csv(written).rename(columns={"time_s": "Zeit", "angle_deg": "Krängung"})
    lab = tmp_path / "versuch_12.csv"
    table.to_csv(lab, index=False)
    url = f"sqlite:///{tmp_path / 'c.sqlite'}"
    code, lines = _cli("identify", lab, "--time-col", "Zeit", "--angle-col", "Krängung", "--catalogue", url)
    assert code == 0 and not [line for line in lines if line.startswith("catalogue:")], lines
    (row,) = json.loads(CliRunner().invoke(app, ["runs", "--json", "--catalogue", url]).stdout)
    assert (Path(row["path"]).name, row["axis"], row["fit_source"]) == (lab.name, "roll", "identify")
    assert row["b1"] > 0 and row["b1_ci_low"] <= row["b1"] <= row["b1_ci_high"]


def test_identify_names_the_column_formats_it_reads(tmp_path: Path) -> None:
    (tmp_path / "run.xlsx").write_bytes(b"PK")
    workbook = r"\(a spreadsheet workbook: save its sheet as CSV\)"
    formats = r"use a \.mcap, \.csv, \.txt, \.h5, \.hdf5, \.mat, \.parquet, \.tdms or \.mtb file"
    with pytest.raises(InputError, match=rf"unknown file type \.xlsx {workbook}; decays: {formats}"):
        tankdaq.read(tmp_path / "run.xlsx")


# ---- frames pandas wrote (DataFrame.to_hdf, through PyTables) ---------------------------------------


def _frame(amplitude_deg: float = 8.0) -> pd.DataFrame:
    t = np.arange(3000) * 0.01
    angle = _decay(amplitude_deg)
    rate = np.gradient(angle, t)
    return pd.DataFrame({"time_s": t, "roll_deg": angle, "roll_rate_deg_s": rate, "tag": ["run"] * t.size})


PANDAS_LAYOUTS = {  # how a lab's notebook saves a frame: pandas' default (fixed), the time as the index,
    # and the two table layouts (the columns in a block named by a pickle, or each a field of its own)
    "fixed": {},
    "fixed, time as index": {"index": "time_s"},
    "table": {"format": "table"},
    "table, data columns": {"format": "table", "data_columns": True},
}


@pytest.mark.parametrize("layout", list(PANDAS_LAYOUTS))
@pytest.mark.slow
def test_a_frame_pandas_saved_to_hdf5_reads_as_the_csv_of_that_frame(tmp_path: Path, layout: str) -> None:
    pytest.importorskip("tables", reason="PyTables (pandas' HDF5 writer) is not installed")
    options = dict(PANDAS_LAYOUTS[layout])
    frame = _frame()
    frame.to_csv(tmp_path / "run.csv", index=False)
    numeric = frame.drop(columns="tag") if options.get("format") == "table" else frame  # text needs a size
    if index := options.pop("index", None):
        numeric = numeric.set_index(index)
    numeric.to_hdf(tmp_path / "run.h5", key="run21", mode="w", **options)
    columns = {"angle_col": "roll_deg", "rate_col": "roll_rate_deg_s"}
    csv, h5 = tankdaq.read(tmp_path / "run.csv", **columns), tankdaq.read(tmp_path / "run.h5", **columns)
    assert len(h5.decays) == len(csv.decays) == 1
    for name in ("t", "angle", "rate"):
        np.testing.assert_array_equal(getattr(h5.decays[0].run, name), getattr(csv.decays[0].run, name))
    assert not any("_i_table" in line or "indicesLR" in line for line in h5.notices)  # PyTables' indexes


def test_several_frames_in_one_file_are_named_by_their_keys(tmp_path: Path) -> None:
    pytest.importorskip("tables", reason="PyTables (pandas' HDF5 writer) is not installed")
    path = tmp_path / "runs.h5"
    _frame(8.0).drop(columns="tag").to_hdf(path, key="run21", mode="w")
    _frame(5.0).drop(columns="tag").to_hdf(path, key="run22", mode="a")
    second = tankdaq.read(path, time_col="run22/time_s", angle_col="run22/roll_deg", rate_col=None)
    assert second.decays[0].initial_angle_deg == pytest.approx(5.0, rel=0.01)
    with pytest.raises(InputError, match="run21/roll_deg"):  # the file's columns named in the one line
        tankdaq.read(path, angle_col="roll_deg")


def test_a_pickle_in_a_pandas_file_is_never_loaded(tmp_path: Path) -> None:
    """The names of a table's block live in a pickled attribute. One that holds code is refused unrun."""
    pytest.importorskip("tables", reason="PyTables (pandas' HDF5 writer) is not installed")
    path, marker = tmp_path / "run.h5", tmp_path / "ran"
    _frame().drop(columns="tag").to_hdf(path, key="run", mode="w", format="table")
    hostile = b"cos\nsystem\n(V" + f"touch {marker}".encode() + b"\ntR."  # os.system("touch ...")
    with h5py.File(path, "r+") as h5:
        h5["run/table"].attrs["values_block_0_kind"] = np.bytes_(hostile)
        h5["extra_time_s"] = np.arange(3000) * 0.01  # one column to read, so the refusal is a note
        h5["extra_roll_deg"] = _decay(8.0)
    rec = tankdaq.read(path, time_col="extra_time_s", angle_col="extra_roll_deg", rate_col=None)
    assert not marker.exists()
    assert any("values_block_0" in line for line in rec.notices)


def test_a_pandas_file_with_nothing_readable_says_why_in_its_one_line(tmp_path: Path) -> None:
    pytest.importorskip("tables", reason="PyTables (pandas' HDF5 writer) is not installed")
    path = tmp_path / "run.h5"
    _frame().drop(columns="tag").to_hdf(path, key="run", mode="w", format="table")
    with h5py.File(path, "r+") as h5:
        h5["run/table"].attrs["values_block_0_kind"] = np.int64(5)  # damaged: no list of names
    with pytest.raises(
        InputError, match=r"values_block_0 is a block of columns whose names are no plain list"
    ):
        tankdaq.read(path, angle_col="roll_deg")
