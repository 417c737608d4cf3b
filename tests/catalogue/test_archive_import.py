"""``tankdaq import FOLDER --out recordings/``: one recording per decay with its provenance, catalogued,
the files that are no decays listed with why, and nothing added the second time."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

import tankdaq
from support.lab_logs import bus_log, samples_of, single_device_log, tdms_file
from tankdaq.api.archive import recording_path
from tankdaq.catalogue.archive import ArchiveReport, import_archive
from tankdaq.cli import app

runner = CliRunner()


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str, dict[str, int]]:
    """A lab's folder: an MTi-G log, an Awinda-like log of 2 devices, a TDMS tow with two decays (the
    carriage at 0.8 then 1.4 m/s, at rest between them), a CSV, and junk; the decays each should give."""
    root = tmp_path_factory.mktemp("archive")
    folder = root / "lab"
    (folder / "2024").mkdir(parents=True)
    single_device_log(folder / "mtig.mtb")
    bus_log(folder / "2024" / "awinda.mtb", devices=2)
    first, second = samples_of(5), samples_of(6)
    roll = np.concatenate([first["roll"], second["roll"]])
    t = np.arange(roll.size) * 0.01
    speed = np.concatenate([np.full(first.size, 0.8), np.full(second.size, 1.4)])
    tdms_file(folder / "2024" / "tow.tdms", t, np.degrees(roll), speed)
    samples = samples_of(7)
    rows = zip((samples["t"] - samples["t"][0]).tolist(), np.degrees(samples["roll"]).tolist(), strict=True)
    (folder / "swath_T_roll_8deg.csv").write_text(
        "time_s,angle_deg\n" + "".join(f"{a},{b}\n" for a, b in rows)
    )
    sidecar = {
        "hull": "swath",
        "draft": "1.1T",
        "axis": "roll",
        "angle_deg": 8,
    }  # read with the CSV, not listed
    (folder / "swath_T_roll_8deg.json").write_text(json.dumps(sidecar))
    (folder / "notes.txt").write_text("carriage log, not a decay\n")  # a text table with no rows
    (folder / "carriage.log").write_text("speed 0.8 m/s\n")  # no reader for its kind
    (folder / "empty.csv").write_text("time_s,angle_deg\n0,1\n")
    (folder / "2024" / "noise.mtb").write_bytes(
        np.random.default_rng(0).integers(0, 256, 4000, np.uint8).tobytes()
    )
    catalogue = f"sqlite:///{root / 'catalogue.sqlite'}"
    expected = {"mtig.mtb": 1, "awinda.mtb": 2, "tow.tdms": 2, "swath_T_roll_8deg.csv": 1}
    return folder, root / "recordings", catalogue, expected


@pytest.fixture(scope="module")
def first(archive: tuple[Path, Path, str, dict[str, int]]) -> ArchiveReport:
    folder, out, catalogue, _ = archive
    return import_archive(folder, out, catalogue=catalogue)


@pytest.mark.slow  # the module's import of the whole folder
def test_every_decay_of_every_file_is_one_recording(
    archive: tuple[Path, Path, str, dict[str, int]], first: ArchiveReport
) -> None:
    _, out, _, expected = archive
    found: dict[str, int] = {}
    for decay in first.imported.decays:
        found[decay.source.name] = found.get(decay.source.name, 0) + 1
    assert found == expected
    assert sorted(p.name for p in out.iterdir()) == sorted(d.path.name for d in first.imported.decays)
    assert all(decay.added for decay in first.imported.decays)
    assert set(first.imported.not_decays) == {
        p for p in archive[0].rglob("*") if p.name in ("notes.txt", "carriage.log", "empty.csv", "noise.mtb")
    }
    assert "not a file tankdaq reads (.log)" in first.imported.not_decays[archive[0] / "carriage.log"]
    assert "0 data rows" in first.imported.not_decays[archive[0] / "notes.txt"]


@pytest.mark.slow
def test_each_recording_holds_its_provenance(first: ArchiveReport) -> None:
    """Read back with the official mcap reader: the source, its SHA-256, its header, the conversions."""
    for decay in first.imported.decays:
        with decay.path.open("rb") as fh:
            records = [m for m in make_reader(fh).iter_metadata() if m.name == "tankdaq.run"]
        meta = records[-1].metadata
        assert meta["source_file"] == str(decay.source.resolve())
        assert meta["source_sha256"] == _sha(decay.source)
        assert int(meta["source_decay"]) == decay.index
        assert json.loads(meta["conversions"])
        header = json.loads(meta["source_header"])
        if decay.source.suffix == ".mtb":
            assert meta["device_id"].startswith("077B1A2") and header["log_date"] == "20241105"
        if decay.source.suffix == ".csv":  # its condition from its sidecar
            assert (meta["hull"], meta["draft"], float(meta["angle_nominal_deg"])) == ("swath", "1.1T", 8.0)
        if decay.source.suffix == ".tdms":
            assert header["tdms_name"] == "tow 12"
            assert float(meta["speed_m_s"]) == pytest.approx(0.8 if decay.index == 1 else 1.4)


@pytest.mark.slow
def test_an_imported_decay_fits_as_its_source(first: ArchiveReport) -> None:
    (imported,) = [d for d in first.imported.decays if d.source.suffix == ".csv"]
    from_source = tankdaq.identify(imported.source, "b1,c1").fits[0].estimator.coefficients_
    from_recording = tankdaq.identify(imported.path, "b1,c1").fits[0].estimator.coefficients_
    assert from_recording == pytest.approx(from_source, rel=1e-9)


@pytest.mark.slow
def test_the_decays_are_catalogued_and_a_second_import_adds_nothing(
    archive: tuple[Path, Path, str, dict[str, int]], first: ArchiveReport
) -> None:
    folder, out, catalogue, expected = archive
    assert first.catalogued is not None and len(first.catalogued.added) == sum(expected.values())
    rows = tankdaq.runs(catalogue=catalogue)
    assert len(rows) == sum(expected.values())
    written = {p: p.stat().st_mtime_ns for p in out.iterdir()}
    result = runner.invoke(app, ["import", str(folder), "--out", str(out), "--catalogue", catalogue])
    assert result.exit_code == 0, result.output
    assert "0 written, 6 imported before" in result.output and "0 added" in result.output
    assert "not a decay: " in result.output and "imported before" in result.output
    assert {p: p.stat().st_mtime_ns for p in out.iterdir()} == written
    assert len(tankdaq.runs(catalogue=catalogue)) == sum(expected.values())


def test_a_file_tankdaq_did_not_write_is_never_replaced(tmp_path: Path) -> None:
    folder, out = tmp_path / "lab", tmp_path / "recordings"
    folder.mkdir()
    source, _ = single_device_log(folder / "mtig.mtb")
    out.mkdir()
    theirs = recording_path(out, source, _sha(source), 1)
    theirs.write_bytes(b"somebody's file")
    found = import_archive(folder, out, catalogue="none")
    assert theirs.read_bytes() == b"somebody's file"
    assert (
        not found.imported.decays
        and "is not this decay's import: left alone" in found.imported.not_written[0]
    )
    assert "1 decays NOT written" in found.line
