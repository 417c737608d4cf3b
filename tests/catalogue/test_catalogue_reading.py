"""The catalogue read safely (issue 37, item 6): a read never makes, migrates or writes a catalogue; a
database that is not tankdaq's is refused and left byte for byte; a writer holding a transaction never
makes a reader wait; a server that never answers is one line after the connect timeout; every URL form
hides its password; every bad URL, path, damaged page or hand-edited column is one line.

SQLite and a real throwaway PostgreSQL server (tests/support/pg_server.py) where both apply.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa
from typer.testing import CliRunner, Result

import tankdaq
from support.catalogue_fresh import fresh_catalogue, table_names
from support.pg_server import free_port
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.catalogue.database import CatalogueError, NoCatalogue, open_catalogue, resolve_url
from tankdaq.cli import app

EXE = str(Path(sys.executable).with_name("tankdaq"))
#: Long enough to catch the 131 s stall and the 30 s lock wait; never a timing the test asserts.
HANG_S = 60.0
SECRET = "Hunter2Secret"


@pytest.fixture(params=["sqlite", "postgresql"])
def catalogue_at(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    yield from fresh_catalogue(request, tmp_path)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four small simulated recordings (swath roll, two drafts, two angles) as lab CSV decays."""
    folder = tmp_path_factory.mktemp("recordings")
    write_simulated_campaign(folder, ["swath"], "roll", [1.0, 1.1], [4.0, 6.0], "csv")
    return folder


def _invoke(*args: str, env: dict[str, str] | None = None) -> Result:
    return CliRunner().invoke(app, list(args), env=env)


def _one_line(result: Result | subprocess.CompletedProcess[str]) -> str:
    """The single error line of a failed command (no traceback, nothing else on stderr)."""
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr + result.stdout
    return lines[0]


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# ---- a read never makes or changes a catalogue ----------------------------------------------------


@pytest.mark.slow
def test_a_read_of_a_path_with_no_catalogue_says_so_and_makes_nothing(tmp_path: Path) -> None:
    typo = tmp_path / "catalouge.sqlite"
    result = _invoke("runs", "--catalogue", str(typo))
    assert result.exit_code == 2
    assert _one_line(result).startswith(f"error: no catalogue at {typo} ")
    by_env = _invoke("runs", "--json", env={"TANKDAQ_CATALOGUE": str(typo)})
    assert by_env.exit_code == 2 and "no catalogue at" in _one_line(by_env)
    with pytest.raises(NoCatalogue, match="no catalogue at"):
        tankdaq.runs(catalogue=str(typo))
    folder = tmp_path / "a folder"
    folder.mkdir()
    assert "no catalogue at" in _one_line(_invoke("runs", "--catalogue", str(folder)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a folder"]  # nothing made, not even a -wal
    assert list(folder.iterdir()) == []


def _foreign_sqlite(folder: Path, kind: str) -> Path:
    """A file that is not a tankdaq catalogue: another application's SQLite (rollback or WAL journal),
    an empty notes.txt, a text file, another tool's ``schema_version`` table."""
    path = folder / {"empty": "notes.txt", "text": "notes.md"}.get(kind, f"{kind}.db")
    if kind == "empty":
        path.touch()
    elif kind == "text":
        path.write_text("# lab notes\nswath at 1.1T: rerun 6 deg\n")
    else:
        with sqlite3.connect(path) as connection:
            if kind == "wal":
                connection.execute("PRAGMA journal_mode = WAL")
            if kind == "schema_version":
                connection.execute("CREATE TABLE schema_version (version TEXT, description TEXT)")
                connection.execute("INSERT INTO schema_version VALUES ('1.0.3', 'flyway baseline')")
            else:
                connection.execute("CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)")
                connection.execute("INSERT INTO customers (name) VALUES ('towing tank')")
        connection.close()
    return path


@pytest.mark.parametrize("kind", ["other", "wal", "empty", "text", "schema_version"])
@pytest.mark.slow
def test_a_file_that_is_not_a_tankdaq_catalogue_is_refused_and_left_byte_identical(
    kind: str, tmp_path: Path, recordings: Path
) -> None:
    path = _foreign_sqlite(tmp_path, kind)
    before, names = _sha(path), sorted(p.name for p in tmp_path.iterdir())
    reading = _invoke("runs", "--catalogue", str(path))
    writing = _invoke("catalogue", "index", str(recordings), "--catalogue", str(path))
    assert (reading.exit_code, writing.exit_code) == (1, 1)
    for result in (reading, writing):
        line = _one_line(result)
        assert "left untouched" in line or "not a database" in line, line
    with pytest.raises(CatalogueError):
        tankdaq.runs(catalogue=str(path))
    assert _sha(path) == before
    after = sorted(p.name for p in tmp_path.iterdir())
    if kind == "wal":  # a WAL database's readers share its -shm index; nothing is written to its -wal
        assert after == sorted([*names, "wal.db-shm", "wal.db-wal"])
        assert path.with_name("wal.db-wal").stat().st_size == 0
    else:
        assert after == names  # no journal, -wal or -shm made


@pytest.mark.slow
def test_another_applications_postgresql_database_is_refused_and_keeps_its_tables(
    catalogue_at: str, recordings: Path
) -> None:
    engine = sa.create_engine(str(resolve_url(catalogue_at)))
    with engine.begin() as connection:
        connection.execute(sa.text("CREATE TABLE invoices (id INTEGER PRIMARY KEY, total REAL)"))
    engine.dispose()
    for args in (["runs"], ["catalogue", "index", str(recordings)]):
        result = _invoke(*args, "--catalogue", catalogue_at)
        assert result.exit_code == 1
        assert "is not a tankdaq catalogue (it holds tables invoices)" in _one_line(result)
    assert table_names(catalogue_at) == ["invoices"]


@pytest.mark.slow
def test_a_writer_may_make_a_new_catalogue_and_a_read_then_lists_it(
    catalogue_at: str, recordings: Path
) -> None:
    made = _invoke("catalogue", "index", str(recordings), "--catalogue", catalogue_at)
    assert made.exit_code == 0, made.output
    assert "4 added" in made.stdout
    frame = tankdaq.runs(catalogue=catalogue_at)
    assert sorted(frame["draft"]) == ["1.1T", "1.1T", "T", "T"]


# ---- waits --------------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_sqlite_writer_holding_a_transaction_never_makes_runs_wait(
    tmp_path: Path, recordings: Path
) -> None:
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    assert _invoke("catalogue", "index", str(recordings), "--catalogue", url).exit_code == 0
    holder = sqlite3.connect(tmp_path / "catalogue.sqlite", isolation_level=None)
    try:
        holder.execute("BEGIN IMMEDIATE")  # what a recorder's catalogue writer holds while it writes
        holder.execute("UPDATE decays SET plan = 'being written'")
        listed = subprocess.run(
            [EXE, "runs", "--json", "--catalogue", url], capture_output=True, text=True, timeout=HANG_S
        )
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert listed.returncode == 0, listed.stderr
    assert '"plan": "being written"' not in listed.stdout  # the committed rows, read beside the writer
    assert listed.stdout.count('"sha256"') == 4


@pytest.mark.parametrize("catalogue_at", ["postgresql"], indirect=True)
@pytest.mark.slow
def test_a_postgresql_writer_holding_a_transaction_never_makes_runs_wait(
    catalogue_at: str, recordings: Path
) -> None:
    request_url = catalogue_at
    assert _invoke("catalogue", "index", str(recordings), "--catalogue", request_url).exit_code == 0
    engine = sa.create_engine(str(resolve_url(request_url)))
    with engine.connect() as holder:
        holder.execute(sa.text("SELECT pg_advisory_xact_lock(24240424)"))  # a writer opening it
        holder.execute(sa.text("UPDATE decays SET plan = 'being written'"))
        listed = subprocess.run(
            [EXE, "runs", "--json", "--catalogue", request_url],
            capture_output=True,
            text=True,
            timeout=HANG_S,
        )
        holder.rollback()
    engine.dispose()
    assert listed.returncode == 0, listed.stderr
    assert listed.stdout.count('"sha256"') == 4 and "being written" not in listed.stdout


@pytest.mark.slow
def test_a_server_that_accepts_and_never_answers_is_one_line_not_a_hang(recordings: Path) -> None:
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)  # the kernel accepts the connection; nothing ever answers it
        url = f"postgresql://lab:{SECRET}@127.0.0.1:{silent.getsockname()[1]}/catalogue"
        # tankdaq's own 10 s, then the URL's own connect_timeout, which wins
        for args, query in ((["runs"], ""), (["catalogue", "index", str(recordings)], "?connect_timeout=2")):
            done = subprocess.run(
                [EXE, *args, "--catalogue", url + query], capture_output=True, text=True, timeout=HANG_S
            )
            assert done.returncode == 1
            line = _one_line(done)
            assert "timeout" in line and "lab:***@127.0.0.1" in line, line
            assert SECRET not in done.stderr + done.stdout


# ---- passwords --------------------------------------------------------------------------------------

#: The parts of a password that holds ``@`` and ``:``, each of which must never be shown.
PIECES = ("Hunter2", "Se@cr", "et:99")
PASSWORD = "Hunter2Se@cret:99"


def _url_forms(port: int) -> list[str]:
    return [
        f"postgres://lab:{SECRET}@127.0.0.1:{port}/catalogue",
        f"postgresql://lab:{SECRET}@127.0.0.1:{port}/catalogue",
        f"postgresql+psycopg2://lab:{SECRET}@127.0.0.1:{port}/catalogue",
        f"postgresql+psycopg://lab:{SECRET}@127.0.0.1:{port}/catalogue",
        f"postgresql://lab@127.0.0.1:{port}/catalogue?password={SECRET}",
        f"postgresql://lab@127.0.0.1:{port}/catalogue?sslmode=disable&password={SECRET}",
        f"postgresql://lab:{PASSWORD}@127.0.0.1:{port}/catalogue",
        f"postgresql://lab:{SECRET}@127.0.0.1:{port}?password={PASSWORD}",
        # what SQLAlchemy itself cannot parse, or a port, host or scheme that is wrong
        f"postgresql://lab:{SECRET}@[::1/catalogue",
        f"postgresql://lab:{SECRET}@127.0.0.1:54x2/catalogue",
        f"postgresql://lab:{SECRET}@127.0.0.1:99999/catalogue",
        f"postgresql://lab:{PASSWORD}@127.0.0.1:/catalogue",
        f"mysql://lab:{SECRET}@127.0.0.1/catalogue",
        f"postgresql://lab:{SECRET}@host one/catalogue",
    ]


def _shows_a_secret(text: str) -> bool:
    return SECRET in text or any(piece in text for piece in PIECES)


@pytest.mark.slow
def test_every_url_form_hides_its_password_in_every_message(recordings: Path) -> None:
    """Nothing listens on the port: every form ends in one line (refused, or not understood)."""
    for url in _url_forms(free_port()):
        for args in (["runs"], ["catalogue", "index", str(recordings)]):
            given = _invoke(*args, "--catalogue", url)
            by_env = _invoke(*args, env={"TANKDAQ_CATALOGUE": url})
            for result in (given, by_env):
                assert result.exit_code in (1, 2), (url, result.output)
                line = _one_line(result)
                assert not _shows_a_secret(result.output), (url, line)
        with pytest.raises(CatalogueError) as raised:
            tankdaq.runs(catalogue=url)
        assert not _shows_a_secret(str(raised.value)), url


@pytest.mark.slow
def test_postgres_is_an_alias_and_every_form_reaches_the_server(postgres_url: str) -> None:
    """``postgres://``, the driver suffixes and ``password=`` in the query are one catalogue."""
    assert postgres_url.startswith("postgresql://")
    rest = postgres_url.removeprefix("postgresql://")
    open_catalogue(postgres_url).close()
    for scheme in ("postgres", "postgresql+psycopg2", "postgresql+psycopg"):
        listed = _invoke("runs", "--json", "--catalogue", f"{scheme}://{rest}")
        assert listed.exit_code == 0, listed.output
    with_query = _invoke("runs", "--json", "--catalogue", f"{postgres_url}?password={SECRET}")
    assert with_query.exit_code == 0 and SECRET not in with_query.output  # trust: the password is unused


# ---- one line, whatever is wrong ---------------------------------------------------------------------


@pytest.mark.parametrize("command", ["runs", "index"])
@pytest.mark.slow
def test_a_path_that_cannot_be_is_one_line(command: str, tmp_path: Path, recordings: Path) -> None:
    args = ["runs"] if command == "runs" else ["catalogue", "index", str(recordings)]
    for path in ("~nosuchuser_tankdaq/catalogue.sqlite", str(tmp_path / ("x" * 300 + ".sqlite"))):
        result = _invoke(*args, "--catalogue", path)
        assert result.exit_code == 2, result.output
        assert _one_line(result).startswith(f"error: catalogue path '{path}'")
    assert list(tmp_path.iterdir()) == []


def _catalogue_with_rows(folder: Path, recordings: Path) -> Path:
    path = folder / "catalogue.sqlite"
    assert _invoke("catalogue", "index", str(recordings), "--catalogue", str(path)).exit_code == 0
    assert not path.with_name("catalogue.sqlite-wal").exists()  # checkpointed: every page in the file
    return path


@pytest.mark.slow
def test_damaged_pages_are_one_line(tmp_path: Path, recordings: Path) -> None:
    path = _catalogue_with_rows(tmp_path, recordings)
    data = bytearray(path.read_bytes())
    page = 4096
    assert len(data) > 3 * page
    data[page:] = bytes((i * 37 + 11) % 256 for i in range(len(data) - page))  # every page but the first
    path.write_bytes(bytes(data))
    for args in (["runs"], ["runs", "--csv"], ["catalogue", "index", str(recordings)]):
        result = _invoke(*args, "--catalogue", str(path))
        assert result.exit_code == 1, result.output
        assert "not usable" in _one_line(result)
    with pytest.raises(CatalogueError, match="not usable"):
        tankdaq.runs(catalogue=str(path))


@pytest.mark.slow
def test_a_hand_edited_json_column_is_one_line(tmp_path: Path, recordings: Path) -> None:
    path = _catalogue_with_rows(tmp_path, recordings)
    with sqlite3.connect(path) as connection:
        connection.execute("UPDATE decays SET warnings = '[\"fit ok\", oops' WHERE id = 2")
    connection.close()
    result = _invoke("runs", "--json", "--catalogue", str(path))
    assert result.exit_code == 1
    assert "a JSON column holds text that is not JSON" in _one_line(result)
    with pytest.raises(CatalogueError, match="not JSON"):
        tankdaq.runs(catalogue=str(path))


def _unreadable(folder: Path, template: Path) -> Path:
    """A decay file that cannot be read: no permission (a user), else a file whose read fails (root
    reads every file: ``/proc/self/mem`` fails with EIO)."""
    bad = folder / "swath_T_roll_9deg_run01.csv"
    if os.geteuid() != 0:
        bad.write_bytes(template.read_bytes())
        bad.chmod(0)
    else:
        bad.symlink_to("/proc/self/mem")
    return bad


@pytest.mark.slow
def test_an_unreadable_file_in_index_is_listed_and_the_others_indexed(
    catalogue_at: str, recordings: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "data"
    folder.mkdir()
    good = sorted(recordings.glob("*.csv"))
    for path in good:
        (folder / path.name).write_bytes(path.read_bytes())
    bad = _unreadable(folder, good[0])
    result = _invoke("catalogue", "index", str(folder), "--catalogue", catalogue_at)
    assert result.exit_code == 0, result.output
    assert f"{len(good)} added, 0 moved, 0 unchanged, 1 skipped" in result.stdout
    assert [line for line in result.stderr.splitlines() if line.startswith("skipped")] == [
        next(line for line in result.stderr.splitlines() if str(bad) in line and "not readable" in line)
    ]
    assert len(tankdaq.runs(catalogue=catalogue_at)) == len(good)


@pytest.mark.slow
def test_a_writers_catalogue_line_hides_the_password_and_the_fit_still_answers(recordings: Path) -> None:
    decay = sorted(recordings.glob("*.csv"))[0]
    for url in _url_forms(free_port())[:8]:  # the forms that parse: the writer's thread fails to connect
        result = _invoke("identify", str(decay), "--model", "b1,c1", "--json", "--catalogue", url)
        assert result.exit_code == 0, result.output
        assert json.loads(result.stdout)["coefficients"]["b1"]["value"] > 0
        said = [line for line in result.stderr.splitlines() if line.startswith("catalogue: ")]
        assert len(said) == 1, result.stderr
        assert "lab:***@" in said[0] or "password=***" in said[0], said[0]
        assert not _shows_a_secret(result.output), url
