"""The run catalogue and the files ``tankdaq export`` writes: every format indexed (HDF5, CSV, Parquet,
MATLAB), tied to its recording and idempotent by SHA-256, and ``tankdaq runs`` / ``tankdaq.runs`` saying
where each run's exports are. Every file here is written by ``tankdaq export``; every catalogue is a
temporary SQLite file.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import sqlalchemy as sa
from scipy.io import savemat
from typer.testing import CliRunner

import tankdaq
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.catalogue.database import open_catalogue, resolve_url
from tankdaq.catalogue.schema import exports
from tankdaq.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two swath roll recordings (4 and 6 deg at 1.1T)."""
    folder = tmp_path_factory.mktemp("recordings")
    return write_simulated_campaign(folder, ["swath"], "roll", [1.1], [4.0, 6.0], "mcap")


def _invoke(*args: object) -> str:
    result = runner.invoke(app, [str(arg) for arg in args])
    assert result.exit_code == 0, result.output
    return result.stdout


def _export(recording: Path, file_format: str, out: Path) -> Path:
    """``tankdaq export`` of one recording: the data file it wrote (a CSV's sidecar left out)."""
    written = [
        Path(line) for line in _invoke("export", recording, "--format", file_format, "--out", out).split()
    ]
    return next(path for path in written if path.suffix == f".{file_format}")


def _exports(url: str) -> dict[str, dict]:
    with open_catalogue(str(resolve_url(url))) as catalogue, catalogue.reading() as connection:
        return {Path(r.path).name: dict(r._mapping) for r in connection.execute(sa.select(exports))}


def _index(folder: Path, url: str) -> str:
    return _invoke("catalogue", "index", folder, "--catalogue", url)


@pytest.mark.slow
def test_parquet_and_mat_exports_are_indexed_tied_to_their_recording_by_hash(
    recordings: list[Path], tmp_path: Path
) -> None:
    pytest.importorskip("pyarrow", reason="the parquet extra is not installed (pip install tankdaq[parquet])")
    folder = tmp_path / "lab"
    folder.mkdir()
    recording = Path(shutil.copy(recordings[0], folder))
    parquet = _export(recording, "parquet", folder / "parquet")
    mat = _export(recording, "mat", folder / "mat")
    savemat(folder / "other_tool.mat", {"x": np.arange(3.0)})  # another tool's files: not exports
    (folder / "not_parquet.parquet").write_bytes(b"PAR1 but nothing else")
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"

    first = _index(folder, url)
    assert "3 added, 0 moved, 0 unchanged, 2 skipped" in first and "2 of those added are exports" in first
    found = _exports(url)
    assert set(found) == {parquet.name, mat.name}
    source = hashlib.sha256(recording.read_bytes()).hexdigest()
    for path, fmt in ((parquet, "parquet"), (mat, "mat")):
        row = found[path.name]
        assert (row["format"], row["source_sha256"]) == (fmt, source)
        assert row["source_path"] == str(recording.resolve())
        assert (row["sha256"], row["size_bytes"]) == (
            hashlib.sha256(path.read_bytes()).hexdigest(),
            path.stat().st_size,
        )

    assert "0 added, 0 moved, 3 unchanged, 2 skipped" in _index(folder, url)
    moved = mat.rename(folder / "elsewhere.mat")
    assert "0 added, 1 moved, 2 unchanged" in _index(folder, url)
    assert set(_exports(url)) == {parquet.name, moved.name}


@pytest.mark.slow
def test_another_tools_files_and_a_missing_pyarrow_are_skipped_with_their_reason(
    recordings: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("pyarrow", reason="the parquet extra is not installed (pip install tankdaq[parquet])")
    folder = tmp_path / "lab"
    folder.mkdir()
    _export(recordings[0], "parquet", folder)
    savemat(folder / "other_tool.mat", {"tankdaq": {"meta": {"format": "not ours"}}})
    (folder / "cut.mat").write_bytes(b"MATLAB 5.0 MAT-file, cut")  # scipy meets it with an IndexError
    with h5py.File(folder / "other_tool.h5", "w") as other:
        other.create_dataset("t", data=[0.0, 0.1])
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # what `import pyarrow` meets where it is absent
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    result = runner.invoke(
        app, ["catalogue", "index", str(folder), "--catalogue", str(tmp_path / "c.sqlite")]
    )
    assert result.exit_code == 0, result.output
    assert "0 added, 0 moved, 0 unchanged, 4 skipped" in result.stdout
    skipped = sorted(line for line in result.stderr.splitlines() if line.startswith("skipped "))
    assert len(skipped) == 4
    assert "not a MATLAB file tankdaq can read" in next(line for line in skipped if "cut.mat" in line)
    assert "needs pyarrow: pip install 'tankdaq[parquet]' (from a clone: pip install '.[parquet]')" in next(
        line for line in skipped if ".parquet" in line
    )
    # another tool's files are read as a lab's decay files: each says why it holds no decay
    assert "no variables that are vectors of numbers" in next(
        line for line in skipped if "other_tool.mat" in line
    )
    assert "2 data rows; a decay needs at least 20" in next(
        line for line in skipped if "other_tool.h5" in line
    )


@pytest.mark.slow
def test_runs_say_where_each_runs_exports_are_in_the_table_json_csv_and_the_api(
    recordings: list[Path], tmp_path: Path, catalogue_url: str
) -> None:
    """HDF5 and CSV of one recording, none of the other; the exports indexed before their recording
    (not tied by hash yet) are found by the path they were exported from."""
    lab, copies = tmp_path / "recordings", tmp_path / "exports"
    lab.mkdir()
    with_exports, without = (Path(shutil.copy(path, lab)) for path in recordings)
    h5 = _export(with_exports, "h5", copies)
    csv = _export(with_exports, "csv", copies)
    url = catalogue_url
    _index(copies, url)  # before the recordings: tied by path, not yet by hash
    assert {row["source_sha256"] for row in _exports(url).values()} == {None}
    _index(lab, url)

    listed = json.loads(_invoke("runs", "--json", "--catalogue", url))
    by_name = {Path(row["path"]).name: row for row in listed}
    assert by_name[with_exports.name]["exports"] == f"{csv.resolve()} | {h5.resolve()}"
    assert by_name[without.name]["exports"] == ""

    files = json.loads(_invoke("runs", "--exports", "--json", "--catalogue", url))
    assert [(Path(f["export"]).name, f["format"], Path(f["recording"]).name) for f in files] == [
        (csv.name, "csv", with_exports.name),
        (h5.name, "h5", with_exports.name),
    ]
    assert {(f["hull"], f["draft"], f["axis"], f["angle_nominal_deg"]) for f in files} == {
        ("swath", "1.1T", "roll", 4.0)
    }
    assert files[1]["sha256"] == hashlib.sha256(h5.read_bytes()).hexdigest()

    csv_out = _invoke("runs", "--exports", "--csv", "--catalogue", url).splitlines()
    assert csv_out[0].startswith("format,export,decay") and str(h5.resolve()) in csv_out[2]
    table = _invoke("runs", "--catalogue", url)
    assert "1 csv, 1 h5" in table and "exports" in table
    assert str(h5.resolve()) in _invoke("runs", "--exports", "--catalogue", url)

    frame = tankdaq.runs(catalogue=url)
    assert dict(zip(frame["path"].map(lambda p: Path(p).name), frame["exports"], strict=True)) == {
        with_exports.name: f"{csv.resolve()} | {h5.resolve()}",
        without.name: "",
    }
    per_file = tankdaq.runs(catalogue=url, exports=True)
    assert list(per_file["format"]) == ["csv", "h5"] and set(per_file["recording"]) == {
        str(with_exports.resolve())
    }


@pytest.mark.slow
def test_runs_exports_and_compare_together_is_one_line(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["runs", "--exports", "--compare", "a", "b", "--catalogue", str(tmp_path / "c.sqlite")]
    )
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == ["error: --exports and --compare: give one"]
