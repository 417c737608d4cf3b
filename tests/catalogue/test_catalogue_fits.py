"""Every fit kept, one reference fit the lab chooses; rows that follow the bytes; how a decay ended.

Each catalogue test runs on SQLite and on a throwaway PostgreSQL server (``empty_url``). Recordings
are real files: simulated decays written as tankdaq recordings, and a ``tankdaq record --port sim``
subprocess for a file catalogued while it is written.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa
from typer.testing import CliRunner

import tankdaq
from tankdaq.campaign.synthetic import (
    SimulatedTest,
    simulated_decay,
    write_simulated_campaign,
    write_simulated_recording,
)
from tankdaq.catalogue.database import open_catalogue, resolve_url
from tankdaq.catalogue.fits import FitMethod, command_line
from tankdaq.catalogue.index import index_folder
from tankdaq.catalogue.query import paths_for
from tankdaq.catalogue.schema import decays, fits, metadata, schema_version
from tankdaq.cli import app
from tankdaq.config.hulls import load_hull
from tankdaq.errors import RecordingError
from tankdaq.ident.estimators import ESTIMATORS
from tankdaq.ident.evolutionary import GeneticSeedFit, GeneticSettings
from tankdaq.records import DecayEnd
from tankdaq.store.reader import read_recording

EXE = str(Path(sys.executable).with_name("tankdaq"))
DEADLINE_S = 120.0


@pytest.fixture
def empty_url(catalogue_url: str) -> str:
    """``catalogue_url`` emptied: the module's PostgreSQL database is shared by its tests."""
    if not catalogue_url.startswith("sqlite"):
        engine = sa.create_engine(resolve_url(catalogue_url) or catalogue_url)
        metadata.drop_all(engine)
        engine.dispose()
    return catalogue_url


def _table(url: str, table: sa.Table) -> list[dict]:
    with open_catalogue(url) as catalogue, catalogue.reading() as connection:
        return [dict(r._mapping) for r in connection.execute(sa.select(table).order_by(table.c.id))]


def _invoke(*args: str) -> str:
    done = CliRunner().invoke(app, list(args))
    assert done.exit_code == 0, done.output
    return done.stdout


@pytest.mark.slow
def test_a_ga_fit_after_an_output_error_fit_leaves_the_reference_and_both_are_listed(
    empty_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the seeds' GA itself, with a small population and few generations (the paper's take a minute)
    quick = partial(GeneticSeedFit, settings=GeneticSettings(population=40, generations=40))
    monkeypatch.setitem(ESTIMATORS, "ga-quick", quick)
    (path,) = write_simulated_campaign(tmp_path / "rec", ["swath"], "roll", [1.0], [8.0], "mcap")
    _invoke("identify", str(path), "--catalogue", empty_url)  # output error, the model the data chose
    (row,) = _table(empty_url, decays)
    (first,) = _table(empty_url, fits)
    assert (first["method"], first["model_by_data"], row["reference_fit_id"]) == (
        "output-error",
        True,
        first["id"],
    )

    _invoke("identify", str(path), "--method", "ga-quick", "--model", "b1,c1", "--catalogue", empty_url)
    (row,) = _table(empty_url, decays)
    oe, ga = _table(empty_url, fits)
    assert (oe, ga["method"], ga["model"]) == (first, "ga", ga["model"])
    assert ga["coefficients"] != oe["coefficients"] and ga["sha256"] == oe["sha256"] == row["sha256"]
    assert row["reference_fit_id"] == oe["id"] and not row["reference_chosen"]
    assert (row["fit_method"], row["coefficients"]) == ("output-error", oe["coefficients"])

    listed = json.loads(_invoke("runs", "--json", "--catalogue", empty_url))
    assert [(r["fit_method"], r["fit_model"]) for r in listed] == [("output-error", oe["model"])]
    every = json.loads(_invoke("runs", "--fits", "all", "--json", "--catalogue", empty_url))
    assert [(f["id"], f["method"], f["reference"]) for f in every] == [
        (oe["id"], "output-error", True),
        (ga["id"], "ga", False),
    ]
    frame = tankdaq.runs(catalogue=empty_url, fits="all")
    assert list(frame["method"]) == ["output-error", "ga"] and list(frame["reference"]) == [True, False]
    assert ga["host"] and ga["command"] == command_line(sys.argv) and ga["software_version"]
    assert ga["settings"]["method"] == "ga-quick" and oe["settings"]["model_choice"]

    said = CliRunner().invoke(app, ["runs", "--set-reference", str(ga["id"]), "--catalogue", empty_url])
    assert said.exit_code == 0 and f"replaces fit {oe['id']} (output-error" in said.output, said.output
    _invoke("identify", str(path), "--catalogue", empty_url)  # a later fit: the lab's choice stays
    (row,) = _table(empty_url, decays)
    assert (row["reference_fit_id"], row["fit_method"], len(_table(empty_url, fits))) == (
        ga["id"],
        "ga",
        3,
    )
    missing = CliRunner().invoke(app, ["runs", "--set-reference", "999", "--catalogue", empty_url])
    assert missing.exit_code == 2 and "no such fit" in missing.output


def test_a_catalogue_command_line_never_keeps_a_password() -> None:
    argv = [
        "tankdaq",
        "identify",
        "a.mcap",
        "--catalogue",
        "postgresql://lab:s3cret@db/x",
        "--x=postgres://a:b@c",
    ]
    assert "s3cret" not in command_line(argv) and ":b@" not in command_line(argv)
    assert "s3cret" not in command_line(["tankdaq", "runs", "--catalogue=postgresql://lab:s3cret@db/x"])


def test_an_older_catalogue_keeps_its_fits_as_reference_fits_when_migrated(tmp_path: Path) -> None:
    (path,) = write_simulated_campaign(tmp_path / "rec", ["swath"], "roll", [1.0], [8.0], "mcap")
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    _invoke("identify", str(path), "--model", "b1,c1", "--catalogue", url)
    (before,) = _table(url, decays)
    with open_catalogue(url) as catalogue, catalogue.engine.begin() as connection:  # back to version 3
        fits.drop(connection)
        for column in ("ended", "fit_method", "reference_fit_id", "reference_chosen", "retired_utc"):
            connection.exec_driver_sql(f"ALTER TABLE decays DROP COLUMN {column}")
        connection.execute(schema_version.delete().where(schema_version.c.version > 3))
    (after,) = _table(url, decays)
    (kept,) = _table(url, fits)
    assert after["reference_fit_id"] == kept["id"] and kept["method"] == FitMethod.UNKNOWN
    assert kept["coefficients"] == before["coefficients"] and after["coefficients"] == before["coefficients"]


def _writing(path_of: dict[str, Path], out: Path) -> bool:
    """A recording under way: on disk with samples and a live fit, no footer yet."""
    files = sorted(out.glob("*.mcap"))
    if not files:
        return False
    try:
        found = read_recording(files[0])
    except RecordingError:
        return False  # opened, nothing on disk yet
    path_of["file"] = files[0]
    return not found.complete and found.samples.size > 0 and bool(found.fits)


@pytest.mark.slow
@pytest.mark.parametrize("recorder_writes", [True, False], ids=["recorder-row", "index-again"])
def test_index_while_record_writes_then_after_it_closes_leaves_one_complete_row(
    empty_url: str, tmp_path: Path, recorder_writes: bool
) -> None:
    out = tmp_path / "rec"
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8", "--runs", "1"]
    args += ["--seed", "0"]  # the same test each time
    own = empty_url if recorder_writes else "none"
    proc = subprocess.Popen(
        [EXE, *args, "--out", str(out), "--viewer", "none", "--sim-speed", "2", "--catalogue", own],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    path_of: dict[str, Path] = {}
    try:
        deadline = time.monotonic() + DEADLINE_S
        while not _writing(path_of, out):  # the file itself says when: samples and a fit, no footer
            assert proc.poll() is None, f"record ended before its file was seen: {proc.communicate()}"
            assert time.monotonic() < deadline, f"no recording under way in {DEADLINE_S} s"
            time.sleep(0.02)
        with open_catalogue(empty_url) as catalogue:
            index_folder(catalogue, out)
        (provisional,) = _table(empty_url, decays)
        assert (provisional["complete"], provisional["ended"]) == (False, "cut")
        assert provisional["b_eq_per_s"] is None  # a partial file's fit never stands as the decay's number
        proc.wait(timeout=DEADLINE_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
        proc.communicate()
    assert proc.returncode == 0
    with open_catalogue(empty_url) as catalogue:
        index_folder(catalogue, out)
    path = path_of["file"]
    recording = read_recording(path)
    (row,) = _table(empty_url, decays)
    assert (row["path"], row["complete"], row["sha256"]) == (str(path.resolve()), True, _sha(path))
    assert DecayEnd(row["ended"]).whole and row["fit_source"] == "record"
    final = {term: value["value"] for term, value in row["coefficients"].items()}
    assert final == pytest.approx(recording.fits[-1]["coefficients"], rel=1e-12)
    assert row["id"] == provisional["id"]  # replaced, not joined by a second row
    listed = json.loads(_invoke("runs", "--json", "--catalogue", empty_url))
    assert [(r["path"], r["complete"]) for r in listed] == [(str(path.resolve()), True)]


def _sha(path: Path) -> str:
    from tankdaq.store.inputs import file_sha256

    return file_sha256(path)


@pytest.mark.slow
def test_a_file_replaced_under_its_name_keeps_one_row_and_its_fit_on_the_bytes_read(
    empty_url: str, tmp_path: Path
) -> None:
    folder = tmp_path / "lab"
    (first,) = write_simulated_campaign(folder, ["swath"], "roll", [1.0], [8.0], "csv", seed=1)
    _invoke("catalogue", "index", str(folder), "--catalogue", empty_url)
    _invoke("identify", str(first), "--catalogue", empty_url)
    (old,) = _table(empty_url, decays)
    other = tmp_path / "other"
    (replacement,) = write_simulated_campaign(other, ["swath"], "roll", [1.0], [8.0], "csv", seed=2)
    first.write_bytes(replacement.read_bytes())  # the same name, other bytes
    _invoke("catalogue", "index", str(folder), "--catalogue", empty_url)
    (row,) = _table(empty_url, decays)
    assert (row["id"], row["sha256"], row["path"]) == (old["id"], _sha(first), old["path"])
    assert row["reference_fit_id"] is None  # the fit read the old bytes: not this file's number
    _invoke("identify", str(first), "--catalogue", empty_url)
    (row,) = _table(empty_url, decays)
    kept = _table(empty_url, fits)
    assert [f["sha256"] for f in kept] == [old["sha256"], row["sha256"]]
    assert row["reference_fit_id"] == kept[1]["id"]


@pytest.mark.slow
def test_a_decay_stopped_3_s_after_release_says_so_and_runs_campaigns_leave_it_out(
    empty_url: str, tmp_path: Path
) -> None:
    folder = tmp_path / "rec"
    whole = write_simulated_campaign(folder, ["swath"], "roll", [1.0], [6.0, 8.0], "mcap")
    test = SimulatedTest(duration_s=3.5)  # held 0.5 s, stopped 3 s after the release
    coefficients = load_hull("swath").simulation_model("roll").coefficients(1.0)
    t, angle, rate = simulated_decay(coefficients, 7.0, test, np.random.default_rng(3))
    labels = ("swath", "roll", 1.0, 7.0)
    stopped = write_simulated_recording(
        folder / "swath_T_roll_7deg_stopped.mcap", labels, t, angle, rate, test, {"ended": "stopped"}
    )
    legacy = write_simulated_recording(  # a file from before DecayEnd: its settle reason only
        folder / "swath_T_roll_7deg_note.mcap", labels, t, angle, rate, test, {"settle_reason": "note"}
    )
    _invoke("catalogue", "index", str(folder), "--catalogue", empty_url)
    _invoke("identify", str(stopped), "--catalogue", empty_url)  # its fit is kept, never its number
    rows = {Path(r["path"]).name: r for r in json.loads(_invoke("runs", "--json", "--catalogue", empty_url))}
    assert (rows[stopped.name]["ended"], rows[legacy.name]["ended"]) == ("stopped", "stopped")
    assert rows[stopped.name]["b_eq_5deg_per_s"] is None and rows[stopped.name]["fit_method"] is None
    table = _invoke("runs", "--catalogue", empty_url)
    assert "stopped" in table
    found = paths_for("hull=swath draft=T", empty_url)
    assert sorted(p.resolve() for p in found) == sorted(p.resolve() for p in whole)
    asked = paths_for("hull=swath draft=T ended=any", empty_url)
    assert {p.resolve() for p in asked} == {p.resolve() for p in [*whole, stopped, legacy]}
    args = ["campaign", "--runs", "hull=swath draft=T", "--model", "b1,c1", "--jobs", "1"]
    done = CliRunner().invoke(app, [*args, "--catalogue", empty_url])
    assert done.exit_code == 0, done.output
    campaigned = {f["path"] for f in _table(empty_url, fits) if f["source"] == "campaign"}
    assert campaigned == {str(p.resolve()) for p in whole}


@pytest.mark.slow
def test_a_path_that_now_holds_a_copy_of_another_file_retires_its_row(empty_url: str, tmp_path: Path) -> None:
    folder = tmp_path / "lab"
    first, second = write_simulated_campaign(folder, ["swath"], "roll", [1.0], [6.0, 8.0], "csv")
    _invoke("identify", str(first), "--catalogue", empty_url)
    _invoke("catalogue", "index", str(folder), "--catalogue", empty_url)
    first.write_bytes(second.read_bytes())  # the 6-deg file's name now holds the 8-deg decay
    said = _invoke("catalogue", "index", str(folder), "--catalogue", empty_url)
    assert "1 row(s) retired" in said
    listed = json.loads(_invoke("runs", "--json", "--catalogue", empty_url))
    assert [r["path"] for r in listed] == [str(second.resolve())]  # each decay once, each path once
    assert len(_table(empty_url, fits)) == 1  # the retired row's fit is kept


@pytest.mark.slow
def test_a_campaign_fit_of_the_datas_model_is_a_reference_a_later_identify_keeps(
    empty_url: str, tmp_path: Path
) -> None:
    folder = tmp_path / "rec"
    (recording,) = write_simulated_campaign(folder, ["swath"], "roll", [1.0], [6.0], "mcap")
    _invoke("campaign", str(folder), "--jobs", "1", "--catalogue", empty_url)  # the model the data choose
    _invoke("identify", str(recording), "--catalogue", empty_url)
    kept = _table(empty_url, fits)
    by_source = {f["source"]: f for f in kept}
    assert by_source["campaign"]["model_by_data"] and by_source["identify"]["model_by_data"]
    (row,) = _table(empty_url, decays)
    assert row["reference_fit_id"] == by_source["campaign"]["id"]  # the first of its rank stays
