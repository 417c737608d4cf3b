"""The run catalogue: index by hash, a killed recorder, two writers at once (SQLite and a throwaway
PostgreSQL server), queries that are never SQL, a campaign by query, and a catalogue that fails.

Every catalogue here is in a temporary folder (``--catalogue`` or ``TANKDAQ_CATALOGUE``; conftest.py
sets the variable for the whole run): no test writes the user's own catalogue.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import pytest
import sqlalchemy as sa
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import tankdaq
import tankdaq.config.hulls
from tankdaq.campaign.groups import group_runs, identify_groups, read_campaign
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.catalogue.database import (
    WRITER_CACHE_KB,
    BadCatalogueQuery,
    Catalogue,
    CatalogueError,
    open_catalogue,
    resolve_url,
)
from tankdaq.catalogue.hooks import CatalogueWriter
from tankdaq.catalogue.index import index_folder
from tankdaq.catalogue.query import RunQuery, paths_for, select_rows
from tankdaq.catalogue.schema import SCHEMA_VERSION, decays, exports, fits, schema_version
from tankdaq.cli import app

EXE = str(Path(sys.executable).with_name("tankdaq"))
HERE = Path(__file__).resolve().parents[1]
DEADLINE_S = 120.0


def _url(folder: Path) -> str:
    return f"sqlite:///{folder / 'catalogue.sqlite'}"


def _rows(url: str) -> list[dict]:
    with open_catalogue(url) as catalogue, catalogue.engine.connect() as connection:
        return [dict(r._mapping) for r in connection.execute(sa.select(decays))]


@pytest.fixture(scope="module")
def campaign_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """36 small synthetic recordings: swath roll at three drafts from twelve angles."""
    folder = tmp_path_factory.mktemp("recordings")
    angles = [2.0 + i for i in range(12)]
    write_simulated_campaign(folder, ["swath"], "roll", [0.9, 1.0, 1.1], angles, "mcap")
    return folder


def test_the_tests_never_touch_the_user_catalogue() -> None:
    assert os.environ["TANKDAQ_CATALOGUE"].startswith(tempfile.gettempdir())
    assert resolve_url(None) == f"sqlite:///{Path(os.environ['TANKDAQ_CATALOGUE']).resolve()}"
    assert resolve_url("none") is None


@pytest.mark.slow
def test_index_36_then_again_then_a_moved_file_follows_by_hash(campaign_folder: Path, tmp_path: Path) -> None:
    folder = tmp_path / "copy"
    shutil.copytree(campaign_folder, folder)
    url = _url(tmp_path)
    with open_catalogue(url) as catalogue:
        report = index_folder(catalogue, folder)
    assert (len(report.added), report.skipped) == (36, [])
    assert len(_rows(url)) == 36

    again = CliRunner().invoke(app, ["catalogue", "index", str(folder), "--catalogue", url])
    assert again.exit_code == 0, again.output
    assert "0 added, 0 moved, 36 unchanged" in again.output
    assert len(_rows(url)) == 36

    moved = folder / "elsewhere" / "moved.mcap"
    moved.parent.mkdir()
    original = folder / "swath_1.1T_roll_7deg_run01.mcap"
    original.rename(moved)
    with open_catalogue(url) as catalogue:
        report = index_folder(catalogue, folder)
    assert (len(report.added), len(report.moved)) == (0, 1)
    rows = _rows(url)
    assert len(rows) == 36
    (row,) = [r for r in rows if r["path"] == str(moved.resolve())]
    assert (row["hull"], row["draft"], row["axis"], row["angle_nominal_deg"]) == (
        "swath",
        "1.1T",
        "roll",
        7.0,
    )
    assert not any(r["path"] == str(original.resolve()) for r in rows)

    frame = tankdaq.runs(hull="swath", draft="1.1T", catalogue=url)
    assert len(frame) == 12 and set(frame["draft"]) == {"1.1T"}


def _table(url: str, table: sa.Table) -> list[dict]:
    with open_catalogue(url) as catalogue, catalogue.engine.connect() as connection:
        return [dict(r._mapping) for r in connection.execute(sa.select(table))]


@pytest.mark.slow
def test_index_takes_lab_csv_decays_and_exports_by_hash(campaign_folder: Path, tmp_path: Path) -> None:
    """A lab's CSV decays are decays (their condition from the name, or unknown); files ``tankdaq
    export`` wrote go to ``exports``, tied to their recording, so no decay is listed twice."""
    from tankdaq.store.export import export_recording

    folder = tmp_path / "lab"
    folder.mkdir()
    recording = shutil.copy(campaign_folder / "swath_T_roll_8deg_run01.mcap", folder)
    named, other = write_simulated_campaign(folder / "csv", ["swath"], "roll", [1.1], [6.0, 8.0], "csv")
    unnamed = other.rename(other.with_name("tank_log_0412.csv"))  # a name that says nothing
    (h5,) = export_recording(recording, "h5", folder / "h5")
    exported_csv = export_recording(recording, "csv", folder / "csv_export")[0]
    (folder / "campaign.csv").write_text("group,b1\nswath,0.1\n")  # a report's table: not a decay
    with h5py.File(folder / "other_tool.h5", "w") as other:  # another tool's HDF5: not an export
        other.create_dataset("t", data=[0.0, 0.1])
    url = _url(tmp_path)
    with open_catalogue(url) as catalogue:
        report = index_folder(catalogue, folder)
    assert (len(report.added), report.exports, len(report.skipped)) == (5, 2, 2)
    assert ["campaign.csv" in line or "other_tool.h5" in line for line in report.skipped] == [True, True]
    rows = {Path(r["path"]).name: r for r in _rows(url)}
    assert set(rows) == {Path(recording).name, named.name, unnamed.name}
    condition = ("hull", "draft", "axis", "angle_nominal_deg", "complete")
    assert tuple(rows[named.name][c] for c in condition) == ("swath", "1.1T", "roll", 6.0, True)
    assert tuple(rows[unnamed.name][c] for c in condition) == (None, None, "roll", None, True)
    assert rows[named.name]["sha256"] == hashlib.sha256(named.read_bytes()).hexdigest()
    source = rows[Path(recording).name]["sha256"]
    copies = {Path(r["path"]).name: r for r in _table(url, exports)}
    assert set(copies) == {h5.name, exported_csv.name}
    assert {(r["format"], r["source_sha256"]) for r in copies.values()} == {("h5", source), ("csv", source)}

    with open_catalogue(url) as catalogue:
        again = index_folder(catalogue, folder)
        assert (len(again.added), len(again.unchanged)) == (0, 5)
        moved = h5.rename(folder / "moved.h5")
        after_move = index_folder(catalogue, folder)
    assert [p.name for p in after_move.moved] == ["moved.h5"]
    assert {Path(r["path"]).name for r in _table(url, exports)} == {"moved.h5", exported_csv.name}
    assert len(_rows(url)) == 3 and moved.is_file()

    identified = CliRunner().invoke(app, ["identify", str(unnamed), "--model", "b1,c1", "--catalogue", url])
    assert identified.exit_code == 0, identified.output
    assert {Path(r["path"]).name: r["fit_source"] for r in _rows(url)}[unnamed.name] == "identify"
    args = ["identify", str(exported_csv), "--model", "b1,c1", "--catalogue", url]
    exported = CliRunner().invoke(app, args)
    assert exported.exit_code == 0, exported.output
    assert len(_rows(url)) == 3  # an export's fit does not make it a decay of its own


def _wait_for(condition: object, proc: subprocess.Popen, what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not condition():  # type: ignore[operator]
        assert proc.poll() is None, f"the process ended before {what}: {proc.communicate()}"
        assert time.monotonic() < deadline, f"no {what} in {DEADLINE_S} s"
        time.sleep(0.02)


def _cut_after_a_catalogued_one(out: Path, url: str) -> bool:
    """One decay closed and catalogued by the recorder itself, the next under way with samples on disk."""
    from tankdaq.errors import RecordingError
    from tankdaq.store.reader import read_recording

    files = sorted(out.glob("*.mcap"))
    if len(files) < 2:
        return False
    try:
        latest = read_recording(files[-1])
    except RecordingError:
        return False  # opened, nothing on disk yet
    if latest.complete or not latest.samples.size:
        return False
    return any(r["complete"] for r in _rows(url))


@pytest.mark.slow
def test_a_recorder_killed_mid_decay_leaves_no_complete_row_until_recover_and_index(tmp_path: Path) -> None:
    out, url = tmp_path / "rec", _url(tmp_path)
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8", "--runs", "3"]
    args += ["--seed", "0"]  # the same test each time
    proc = subprocess.Popen(
        [EXE, *args, "--out", str(out), "--viewer", "none", "--sim-speed", "8", "--catalogue", url],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_for(lambda: _cut_after_a_catalogued_one(out, url), proc, "second decay under way")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
        proc.communicate()
    first, cut = sorted(out.glob("*.mcap"))
    assert [(r["path"], r["complete"]) for r in _rows(url)] == [(str(first.resolve()), True)]
    (live,) = _rows(url)
    assert live["fit_source"] == "record" and live["coefficients"]["b1"]["value"] > 0  # the live final fit
    hull_file = Path(tankdaq.config.hulls.load_hull("swath").path)  # the hull's version it was recorded with
    assert live["hull_sha256"] == hashlib.sha256(hull_file.read_bytes()).hexdigest()
    run = [EXE, "catalogue", "index", str(out), "--catalogue", url]
    assert subprocess.run(run, capture_output=True, timeout=120).returncode == 0
    assert {r["path"]: r["complete"] for r in _rows(url)} == {
        str(first.resolve()): True,
        str(cut.resolve()): False,
    }

    recovered = out / "recovered.mcap"
    done = subprocess.run(
        [EXE, "recover", str(cut), "--out", str(recovered)], capture_output=True, timeout=120
    )
    assert done.returncode in (0, 3), done.stderr
    assert subprocess.run(run, capture_output=True, timeout=120).returncode == 0
    complete = {r["path"] for r in _rows(url) if r["complete"]}
    assert complete == {str(first.resolve()), str(recovered.resolve())}


# -- two writers at once ---------------------------------------------------------------------------


def _two_writers(url: str, go: Path) -> None:
    writer = str(HERE / "support/catalogue_writer.py")
    procs = [
        subprocess.Popen(
            [sys.executable, writer, url, tag, "1000", str(go)], stdout=subprocess.PIPE, text=True
        )
        for tag in ("first", "second")
    ]
    try:
        for proc in procs:
            assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        go.touch()
        for proc in procs:
            assert proc.wait(timeout=300) == 0
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=30)
            if proc.stdout is not None:
                proc.stdout.close()


def _count(url: str) -> int:
    with open_catalogue(url) as catalogue, catalogue.engine.connect() as connection:
        return int(connection.execute(sa.select(sa.func.count()).select_from(decays)).scalar_one())


@pytest.mark.slow
def test_two_processes_writing_1000_rows_each_into_sqlite_make_2000(tmp_path: Path) -> None:
    url = _url(tmp_path)
    _two_writers(url, tmp_path / "go")
    assert _count(url) == 2000


@pytest.mark.slow
def test_two_processes_writing_1000_rows_each_into_postgresql_make_2000(
    postgres_url: str, tmp_path: Path
) -> None:
    _two_writers(postgres_url, tmp_path / "go")
    url = resolve_url(postgres_url)
    assert url is not None and url.startswith("postgresql+psycopg://")
    assert _count(url) == 2000


# -- queries -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "where",
    [
        "hull = 'x'; drop table decays",
        "hull = x or 1 = 1",
        "1 = 1",
        "hull) = x",
        "no_such_column = 3",
        "r2 >= fast",
    ],
)
@pytest.mark.slow
def test_a_where_that_is_not_the_language_is_one_line_and_touches_nothing(where: str, tmp_path: Path) -> None:
    url = _url(tmp_path)
    result = CliRunner().invoke(app, ["runs", "--where", where, "--catalogue", url])
    assert result.exit_code == 2
    assert result.output.count("\n") == 1 and result.output.startswith("error: --where")


@pytest.mark.slow
def test_a_value_is_a_bound_parameter_never_sql(campaign_folder: Path, tmp_path: Path) -> None:
    url = _url(tmp_path)
    with open_catalogue(url) as catalogue:
        index_folder(catalogue, campaign_folder)
        hostile = RunQuery(where="hull = \"swath' OR '1'='1\"")
        assert select_rows(catalogue, hostile) == []
        assert len(select_rows(catalogue, RunQuery(where="angle >= 10 and draft = 0.9T"))) == 4
    assert _count(url) == 36


@pytest.mark.parametrize("given", ["mysql://lab/runs", "postgresql+asyncpg://x/y"])
def test_a_catalogue_that_is_not_one_is_refused_before_work_in_one_line(given: str) -> None:
    result = CliRunner().invoke(app, ["runs", "--catalogue", given])
    assert result.exit_code == 2 and result.output.count("\n") == 1
    assert result.output.startswith(f"error: catalogue {given!r}: give a path")


def test_a_recorders_writer_keeps_a_small_page_cache_and_queries_keep_sqlites(tmp_path: Path) -> None:
    url = _url(tmp_path)
    writer = CatalogueWriter(url, lambda line: None)
    try:
        assert writer.submit(_cache_size).result(timeout=60) == -WRITER_CACHE_KB
    finally:
        writer.close()
    with open_catalogue(url) as catalogue:
        assert _cache_size(catalogue) == -2000  # SQLite's own


def _cache_size(catalogue: Catalogue) -> int:
    with catalogue.engine.connect() as connection:
        return int(connection.exec_driver_sql("PRAGMA cache_size").scalar_one())


def test_a_newer_schema_is_refused_in_one_line(tmp_path: Path) -> None:
    url = _url(tmp_path)
    with open_catalogue(url) as catalogue, catalogue.engine.begin() as connection:
        assert connection.execute(sa.select(sa.func.max(schema_version.c.version))).scalar() == SCHEMA_VERSION
        connection.execute(schema_version.insert().values(version=99, applied_utc="later"))
    with pytest.raises(CatalogueError, match="newer than this tankdaq"):
        open_catalogue(url)


@pytest.mark.slow
def test_a_campaign_by_query_equals_the_campaign_by_paths(campaign_folder: Path, tmp_path: Path) -> None:
    url = _url(tmp_path)
    with open_catalogue(url) as catalogue:
        index_folder(catalogue, campaign_folder)
    chosen = sorted(campaign_folder.glob("swath_1.1T_roll_[45]deg_run01.mcap"))
    found = paths_for("hull=swath draft=1.1T angle=4", url) + paths_for("hull=swath draft=1.1T angle=5", url)
    assert sorted(p.resolve() for p in found) == [p.resolve() for p in chosen]

    def fitted(paths: list[Path]) -> list[dict[str, float]]:
        results = identify_groups(group_runs(read_campaign(paths).runs), "b1,b2,c1,c3")
        return [dict(r.fit.coefficients_) for r in results if r.fit is not None]

    by_paths, by_query = fitted(chosen), fitted(found)
    assert len(by_paths) == 2
    for a, b in zip(by_paths, by_query, strict=True):
        assert a.keys() == b.keys() and all(abs(a[k] - b[k]) <= 1e-12 * max(1.0, abs(a[k])) for k in a)

    args = ["campaign", "--model", "b1,b2,c1,c3", "--jobs", "1", "--catalogue", url]
    by_cli_paths = CliRunner().invoke(app, [*args, *map(str, chosen)])
    by_cli_query = CliRunner().invoke(app, [*args, "--runs", "hull=swath draft=1.1T since=2000 angle=4"])
    assert by_cli_paths.exit_code == 0 and by_cli_query.exit_code == 0, by_cli_query.output
    assert by_cli_paths.stdout.splitlines()[2] in by_cli_query.stdout  # the 4-deg group's row, as by paths
    written = {r["path"]: r for r in _rows(url) if r["fit_source"] == "campaign"}
    assert set(written) == {str(p.resolve()) for p in chosen}
    for row in written.values():
        fit = by_paths[0] if "_4deg_" in row["path"] else by_paths[1]
        assert {k: v["value"] for k, v in row["coefficients"].items()} == pytest.approx(fit, rel=1e-12)
        assert row["b_eq_per_s"]["5"] > 0 and row["b44_hat"]["5"] > 0  # swath gives beam and displacement

    compared = CliRunner().invoke(
        app, ["runs", "--compare", "draft=1.1T angle=4", "draft=1.1T angle=5", "--json", "--catalogue", url]
    )
    assert compared.exit_code == 0, compared.output
    four, five = sorted(json.loads(compared.stdout), key=lambda row: row["angle_nominal_deg"])
    assert (four["n_a"], four["n_b"], five["n_a"], five["n_b"]) == (1, 0, 0, 1)  # A: 4 deg, B: 5 deg
    assert four["b_eq_5deg_per_s_a"] == pytest.approx(
        next(r["b_eq_per_s"]["5"] for r in written.values() if "_4deg_" in r["path"]), rel=1e-12
    )


def test_runs_with_a_query_no_recording_matches_is_one_line(tmp_path: Path) -> None:
    # a read never makes one (tests/catalogue/test_catalogue_reading.py)
    open_catalogue(_url(tmp_path)).close()
    with pytest.raises(BadCatalogueQuery, match="no complete recording"):
        paths_for("hull=nothing_here", _url(tmp_path))


# -- a catalogue that fails never costs a file -------------------------------------------------------


@pytest.mark.slow
def test_a_corrupt_catalogue_is_one_line_and_identify_still_answers(
    campaign_folder: Path, tmp_path: Path
) -> None:
    corrupt = tmp_path / "corrupt.sqlite"
    corrupt.write_bytes(b"this is not a database " * 400)
    recording = campaign_folder / "swath_T_roll_8deg_run01.mcap"
    before = recording.read_bytes()
    args = ["identify", str(recording), "--model", "b1,c1", "--json"]
    result = CliRunner().invoke(app, [*args, "--catalogue", str(corrupt)])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["coefficients"]["b1"]["value"] > 0
    assert [line for line in result.stderr.splitlines() if "catalogue" in line] == [
        next(line for line in result.stderr.splitlines() if line.startswith("catalogue: "))
    ]
    assert recording.read_bytes() == before

    good = _url(tmp_path)
    assert CliRunner().invoke(app, [*args, "--catalogue", good]).exit_code == 0
    (row,) = _rows(good)
    assert (row["fit_source"], row["path"]) == ("identify", str(recording.resolve()))
    assert row["coefficients"]["b1"]["ci_low"] < row["coefficients"]["b1"]["value"]


@pytest.mark.slow
def test_a_campaigns_fits_go_in_batches_and_one_that_fails_is_one_line(
    campaign_folder: Path, tmp_path: Path
) -> None:
    """A campaign's group fits are held as columns (not fits) and written a batch to a transaction, the
    rest at close; a result the catalogue cannot take is its one line, never the campaign's error."""
    paths = sorted(campaign_folder.glob("swath_1.1T_*.mcap"))[:4]
    results = identify_groups(group_runs(read_campaign(paths).runs), "b1,c1")
    url = _url(tmp_path)
    lines: list[str] = []
    writer = CatalogueWriter(url, lines.append)
    writer.add_campaign(results)
    assert not (tmp_path / "catalogue.sqlite").exists()  # fewer than a batch: nothing written yet
    writer.add_campaign([object()])  # not a campaign's result
    writer.close()
    assert len(lines) == 1 and lines[0].startswith("catalogue: ") and "index" in lines[0]
    written = {r["path"]: r for r in _rows(url)}
    assert set(written) == {str(p.resolve()) for p in paths}
    assert all(row["fit_source"] == "campaign" and row["b44_hat"]["5"] > 0 for row in written.values())


@pytest.mark.slow
def test_a_locked_catalogue_is_one_line_and_never_holds_the_caller(
    campaign_folder: Path, tmp_path: Path
) -> None:
    url = _url(tmp_path)
    open_catalogue(url).close()
    lines: list[str] = []
    holder = sa.create_engine(url).connect()
    writer = CatalogueWriter(url, lines.append)
    try:
        holder.exec_driver_sql("BEGIN EXCLUSIVE")  # another process's long write, as the writer sees it
        writer.add_files([campaign_folder / "swath_T_roll_8deg_run01.mcap"])
        writer.close(wait_s=0.5)
        assert len(lines) == 1 and "still busy" in lines[0] and "catalogue index" in lines[0]
    finally:
        holder.rollback()
        holder.close()
        writer.close()  # the lock gone, the queued write lands: the writer's thread ends here
    assert lines[1:] == [] and len(_rows(url)) == 1


@pytest.fixture(scope="module")
def empty_catalogue(tmp_path_factory: pytest.TempPathFactory) -> str:
    url = _url(tmp_path_factory.mktemp("where"))
    open_catalogue(url).close()
    return url


@settings(max_examples=60, deadline=None)
@given(text=st.text(alphabet=st.sampled_from(list("hulraswt2=<>!~'\";-() _*%\\0")), max_size=40))
def test_any_where_text_is_conditions_or_one_refusal_never_sql(empty_catalogue: str, text: str) -> None:
    """Whatever is typed: bound conditions that run, or ``BadCatalogueQuery``; the table stays whole."""
    try:
        conditions = RunQuery(where=text).conditions()
    except BadCatalogueQuery as exc:
        assert "\n" not in str(exc)
        return
    with open_catalogue(empty_catalogue) as catalogue, catalogue.engine.connect() as connection:
        assert connection.execute(sa.select(decays).where(*conditions)).all() == []
        count = sa.select(sa.func.count()).select_from(schema_version)
        assert connection.execute(count).scalar_one() == SCHEMA_VERSION  # one row per migration, no more


@pytest.mark.slow
def test_identify_and_diagnose_by_query_read_what_the_paths_read(
    campaign_folder: Path, tmp_path: Path
) -> None:
    url = _url(tmp_path)
    with open_catalogue(url) as catalogue:
        index_folder(catalogue, campaign_folder)
    path = campaign_folder / "swath_0.9T_roll_6deg_run01.mcap"
    base = ["identify", "--model", "b1,c1", "--json", "--catalogue", url]
    by_path = CliRunner().invoke(app, [*base, str(path)])
    by_query = CliRunner().invoke(app, [*base, "--runs", "hull=swath draft=0.9T angle=6"])
    assert by_path.exit_code == 0 and by_query.exit_code == 0, by_query.output
    assert json.loads(by_query.stdout)["coefficients"] == json.loads(by_path.stdout)["coefficients"]
    both = CliRunner().invoke(app, [*base, str(path), "--runs", "hull=swath"])
    assert both.exit_code == 2 and both.output.strip() == "error: give files or --runs QUERY, not both"
    diagnosed = CliRunner().invoke(
        app, ["diagnose", "--runs", "hull=swath draft=0.9T angle=6", "--max-steps", "0", "--catalogue", url]
    )
    assert diagnosed.exit_code == 0, diagnosed.output
    (row,) = [r for r in _rows(url) if r["path"] == str(path.resolve())]
    kept = [f for f in _table(url, fits) if f["decay_id"] == row["id"]]
    assert [f["source"] for f in kept] == ["identify", "identify", "diagnose"]  # every fit kept
    assert kept[-1]["coefficients"]["b1"]["value"] > 0 and kept[-1]["sha256"] == row["sha256"]
    assert row["reference_fit_id"] == kept[0]["id"]  # a later fit never replaces the reference
