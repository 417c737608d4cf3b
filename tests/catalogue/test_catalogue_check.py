"""``tankdaq catalogue check URL`` on a SQLite file and on a real PostgreSQL server that asks for a
password: connected or the one-line reason (the password never shown), the schema version, row counts;
a password from a ``.pgpass`` file when the URL has none; without psycopg, the line names the extra."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

import pytest
import sqlalchemy as sa
from typer.testing import CliRunner

from tankdaq.catalogue.database import open_catalogue, resolve_url
from tankdaq.catalogue.schema import SCHEMA_VERSION, hulls, schema_version, sessions
from tankdaq.cli import app

PASSWORD = "Tank@lab:42/s3cret"  # what a URL would have to escape: @ : /


@pytest.fixture(scope="module")
def guarded_url() -> Iterator[str]:
    """A throwaway PostgreSQL server whose role ``tankdaq`` has ``PASSWORD`` (scram); its URL has none."""
    from support.pg_server import throwaway_postgres, why_not

    reason = why_not()
    if reason is not None:
        pytest.skip(reason)
    with throwaway_postgres(password=PASSWORD) as url:
        yield url


def _with_password(url: str, password: str) -> str:
    from urllib.parse import quote

    return url.replace("tankdaq@", f"tankdaq:{quote(password, safe='')}@", 1)


def _add_rows(url: str, hull_count: int, session_count: int) -> None:
    """A catalogue made by tankdaq, then rows written beside it (so the counts are known here)."""
    open_catalogue(url).close()
    now = datetime.now(UTC).isoformat()
    engine = sa.create_engine(str(resolve_url(url)))
    with engine.begin() as connection:
        for index in range(hull_count):
            connection.execute(
                sa.insert(hulls).values(
                    sha256=f"{index:064d}", name=f"h{index}", path="-", content="", first_seen_utc=now
                )
            )
        for index in range(session_count):
            connection.execute(
                sa.insert(sessions).values(session_id=f"s{index}", folder="-", updated_utc=now)
            )
    engine.dispose()


def _check(url: str, env: dict[str, str | None] | None = None) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["catalogue", "check", url], env=env)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result.exit_code, result.output


@pytest.mark.slow
def test_a_sqlite_catalogue_its_version_and_counts_and_a_newer_one_refused(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    code, out = _check(url)
    assert code == 1 and "no catalogue at" in out and not (tmp_path / "catalogue.sqlite").exists()
    _add_rows(url, hull_count=3, session_count=2)
    code, out = _check(str(tmp_path / "catalogue.sqlite"))  # a path, as --catalogue takes
    assert code == 0, out
    assert "connected (SQLite " in out
    version = f"schema version {SCHEMA_VERSION} (this tankdaq's: {SCHEMA_VERSION})"
    assert f"{version}: this tankdaq reads and writes it" in out
    assert "hulls 3" in out and "sessions 2" in out and "decays 0" in out
    engine = sa.create_engine(url)
    with engine.begin() as connection:  # the last migration's mark taken away: an older catalogue
        connection.execute(sa.delete(schema_version).where(schema_version.c.version == SCHEMA_VERSION))
    code, out = _check(url)
    assert code == 0 and f"schema version {SCHEMA_VERSION - 1} " in out and "migrates it" in out, out
    with engine.begin() as connection:
        connection.execute(sa.insert(schema_version).values(version=SCHEMA_VERSION, applied_utc="now"))
        connection.execute(sa.insert(schema_version).values(version=SCHEMA_VERSION + 1, applied_utc="later"))
    engine.dispose()
    code, out = _check(url)
    assert code == 1 and "newer than this tankdaq" in out and "upgrade tankdaq" in out
    assert len(out.strip().splitlines()) == 1


@pytest.mark.slow
def test_postgresql_password_from_a_pgpass_file_when_the_url_has_none(
    guarded_url: str, tmp_path: Path
) -> None:
    pgpass = tmp_path / "pgpass"
    host_port = guarded_url.split("@", 1)[1].split("/", 1)[0]
    escaped = PASSWORD.replace("\\", "\\\\").replace(":", "\\:")
    pgpass.write_text(f"{host_port}:*:tankdaq:{escaped}\n")
    pgpass.chmod(0o600)
    env: dict[str, str | None] = {"PGPASSFILE": str(pgpass), "PGPASSWORD": None}
    code, out = _check(guarded_url, env={"PGPASSFILE": str(tmp_path / "absent"), "PGPASSWORD": None})
    assert code == 1 and "password" in out, out  # without the file the server asks for one
    code, out = _check(guarded_url, env=env)
    assert code == 0 and "no catalogue yet" in out and "connected (PostgreSQL " in out, out
    _add_rows(_with_password(guarded_url, PASSWORD), hull_count=2, session_count=1)
    code, out = _check(guarded_url, env=env)
    assert code == 0, out
    assert f"schema version {SCHEMA_VERSION} " in out and "hulls 2" in out and "sessions 1" in out
    assert PASSWORD not in out


@pytest.mark.slow
def test_a_wrong_password_is_one_line_without_the_password(guarded_url: str) -> None:
    wrong = "Wr0ng@pass:word"
    code, out = _check(_with_password(guarded_url, wrong), env={"PGPASSFILE": "/nonexistent"})
    assert code == 1
    assert len(out.strip().splitlines()) == 1, out
    assert "password authentication failed" in out and "***" in out
    assert wrong not in out and "Wr0ng" not in out and PASSWORD not in out


#: A child without psycopg (``sys.modules['psycopg'] = None``: as if the extra were not installed) that
#: runs each command given as a JSON list and prints its exit code and output as JSON.
BLOCKED = """
import json, sys
sys.modules["psycopg"] = None
from typer.testing import CliRunner
from tankdaq.cli import app
for command in json.loads(sys.argv[1]):
    result = CliRunner().invoke(app, command)
    print(json.dumps([result.exit_code, result.output, repr(result.exception)]))
"""


@pytest.mark.slow
def test_without_psycopg_every_postgresql_opening_names_the_extra(tmp_path: Path) -> None:
    url = "postgresql://tankdaq:hidden@127.0.0.1:9/tankdaq"
    commands = [
        ["catalogue", "check", url],
        ["runs", "--catalogue", url],  # a reader
        ["catalogue", "index", str(tmp_path), "--catalogue", url],  # a writer
    ]
    done = subprocess.run(
        [sys.executable, "-c", BLOCKED, json.dumps(commands)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    results = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(results) == len(commands)
    for command, (code, output, exception) in zip(commands, results, strict=True):
        assert code == 1, (command, output, exception)
        assert "pip install 'tankdaq[postgres]'" in output, (command, output)
        assert "hidden" not in output and "Traceback" not in output
