"""The catalogue opened: to write (made and migrated where new) or to read only (never made, migrated or
written), either way refusing another application's database.

The catalogue is an index of files, never their only copy, so a catalogue that cannot be opened is one
line (``CatalogueError``, its password masked), never a lost recording. Its tables and migrations are
``catalogue.schema``; where it lives, ``catalogue.location``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import sqlalchemy as sa

from ..errors import install_hint
from .location import ENV_VAR as ENV_VAR
from .location import FILE_NAME as FILE_NAME
from .location import BadCatalogueQuery as BadCatalogueQuery
from .location import CatalogueError, NoCatalogue, describe, resolve_url, scrub, sqlite_path
from .schema import SCHEMA_VERSION, metadata, migrate, schema_version

T = TypeVar("T")

#: How long a writer waits for another one's lock before giving up (SQLite), in ms.
BUSY_TIMEOUT_MS = 30_000
#: The execution option that marks a connection as a reader (``Catalogue.reading``).
READ_ONLY = "tankdaq_read_only"
#: How many values one look-up asks for (a bound parameter list, well under every driver's limit).
LOOKUP_BATCH = 500


def in_batches(values: Sequence[T]) -> Iterator[Sequence[T]]:
    """``values`` in slices of at most ``LOOKUP_BATCH``: one look-up's ``IN`` list each."""
    for start in range(0, len(values), LOOKUP_BATCH):
        yield values[start : start + LOOKUP_BATCH]


@dataclass
class Catalogue:
    """An open catalogue: ``engine`` and the URL it came from (``open_catalogue``, ``read_catalogue``).
    A database error inside ``with`` (a damaged page, a JSON column edited by hand) leaves it as one
    ``CatalogueError`` line."""

    url: str
    engine: sa.Engine

    def reading(self) -> sa.Connection:
        """A connection that only reads: on SQLite a deferred BEGIN, so it never takes the write lock
        (WAL readers do not wait for writers, nor writers for them)."""
        return self.engine.connect().execution_options(**{READ_ONLY: True})

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Catalogue:
        return self

    def __exit__(self, kind: object, exc: BaseException | None, trace: object) -> None:
        self.close()
        if isinstance(exc, sa.exc.SQLAlchemyError | json.JSONDecodeError):
            raise failure(self.url, exc) from None


#: SQLite's page cache for a recorder's catalogue writer: it appends a row a decay, so a small cache
#: costs it nothing, while SQLite's own 2 MB would fill over a lab day and grow the recorder by as much
#: (``bench/bench_memory_day.py``; the pages stay in the system's file cache).
WRITER_CACHE_KB = 256
#: How long a PostgreSQL connection may take to be made, in s (libpq's ``connect_timeout``): a server
#: that accepts and never answers is one line after this, not a 131 s stall.
CONNECT_TIMEOUT_S = 10
#: What an empty existing file may be called for a writer to make it a catalogue (``touch x.sqlite``);
#: any other empty file (``notes.txt``) is a user's, never turned into a database.
SQLITE_SUFFIXES = (".sqlite", ".sqlite3", ".db")
SQLITE_HEADER = b"SQLite format 3\x00"
ELSEWHERE = "give a tankdaq catalogue or a new path"
#: What opening a catalogue may raise besides ``CatalogueError`` (ValueError: a JSON column that does not
#: parse, a path that is not text).
OPEN_FAILURES = (sa.exc.SQLAlchemyError, OSError, ImportError, ValueError)


def failure(url: str, exc: BaseException) -> CatalogueError:
    """What went wrong with the catalogue at ``url``, as one line without its password."""
    why = one_line(exc)
    if isinstance(exc, json.JSONDecodeError):
        why = f"a JSON column holds text that is not JSON (edited by hand?): {exc.msg}"
    return CatalogueError(f"catalogue {describe(url)} not usable: {scrub(why, url)}")


def open_catalogue(url: str, cache_kb: int | None = None) -> Catalogue:
    """Connect, create or migrate the schema (for a writer); SQLite in WAL mode with a busy timeout, so
    several recorders and an analysis write at once. Another application's database is refused and left
    as it was. Whatever fails is one ``CatalogueError`` line.
    ``cache_kb``: SQLite's page cache per connection (None: SQLite's own, 2 MB; ``WRITER_CACHE_KB``)."""
    url = resolve_url(url) or url
    try:
        path = sqlite_path(url)
        if path is not None and path.exists():
            _refuse_foreign_file(url, path)  # looked at read-only, before WAL mode would change it
        engine = _engine(url, cache_kb)
        with engine.begin() as connection:
            check_schema(connection, url, writing=True)
            migrate(connection)
    except CatalogueError:
        raise
    except OPEN_FAILURES as exc:
        raise failure(url, exc) from None
    return Catalogue(url, engine)


def read_catalogue(url: str) -> Catalogue:
    """Open to read only (``runs``, ``--runs``, ``tankdaq.runs``): never created, migrated or written.
    A file that is not there is "no catalogue at X"; a database tankdaq did not make is refused,
    untouched; the schema check reads without the write lock, so a writer never makes it wait."""
    url = resolve_url(url) or url
    try:
        engine = _reader_engine(url)
        with Catalogue(url, engine).reading() as connection, connection.begin():
            check_schema(connection, url, writing=False)
    except CatalogueError:
        raise
    except OPEN_FAILURES as exc:
        raise failure(url, exc) from None
    return Catalogue(url, engine)


def _refuse_foreign_file(url: str, path: Path) -> None:
    """An existing file a writer was pointed at: a tankdaq catalogue (or an empty ``.sqlite``), else
    refused, its bytes untouched."""
    if path.stat().st_size == 0:
        if path.suffix.lower() in SQLITE_SUFFIXES:
            return
        raise CatalogueError(f"{path} is an empty file, not a catalogue: left untouched; give another path")
    with path.open("rb") as file:
        if file.read(len(SQLITE_HEADER)) != SQLITE_HEADER:
            raise CatalogueError(f"{path} is not a SQLite database: left untouched; give another path")
    engine = _reader_engine(url)
    try:
        with Catalogue(url, engine).reading() as connection, connection.begin():
            check_schema(connection, url, writing=True)
    finally:
        engine.dispose()


def check_schema(connection: sa.Connection, url: str, writing: bool) -> int:
    """Refuse a database that is not tankdaq's (another application's tables, another tool's
    ``schema_version``) and one newer than this tankdaq; a reader also one it would have to migrate.
    Only reads (the caller's transaction: a reader's takes no write lock). Its schema version (0: new)."""
    where = f"catalogue {describe(url)}"
    names = set(sa.inspect(connection).get_table_names())
    if "schema_version" not in names:
        if writing and not names:
            return 0  # a new catalogue
        held = f"it holds tables {', '.join(sorted(names)[:6])}" if names else "it holds no table"
        raise CatalogueError(f"{where} is not a tankdaq catalogue ({held}): left untouched; {ELSEWHERE}")
    columns = {column["name"] for column in sa.inspect(connection).get_columns("schema_version")}
    if columns != set(schema_version.c.keys()):
        raise CatalogueError(
            f"{where} is not a tankdaq catalogue (another tool's schema_version table): left untouched; "
            + ELSEWHERE
        )
    found = connection.execute(sa.select(sa.func.max(schema_version.c.version))).scalar() or 0
    if not isinstance(found, int):
        raise CatalogueError(f"{where}: its schema_version holds {found!r}, not a version: left untouched")
    if found > SCHEMA_VERSION:
        raise CatalogueError(
            f"catalogue schema version {found} is newer than this tankdaq's ({SCHEMA_VERSION}): "
            "upgrade tankdaq"
        )
    missing = sorted(set(metadata.tables) - names)
    if not writing and (found < SCHEMA_VERSION or missing):
        raise CatalogueError(
            f"{where} is at schema version {found} (this tankdaq's: {SCHEMA_VERSION}"
            + (f"; missing {', '.join(missing)}" if missing else "")
            + "): a read never changes it; `tankdaq catalogue index FOLDER` brings it up to date"
        )
    return found


def _engine(url: str, cache_kb: int | None) -> sa.Engine:
    parsed = sa.make_url(url)
    if parsed.get_backend_name() != "sqlite":
        return _server_engine(url)
    if parsed.database:
        Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
    engine = sa.create_engine(url, connect_args={"timeout": BUSY_TIMEOUT_MS / 1000})
    pragmas = ["PRAGMA journal_mode = WAL", "PRAGMA synchronous = NORMAL"]
    if cache_kb is not None:
        pragmas.append(f"PRAGMA cache_size = {-int(cache_kb)}")  # negative: KiB, not pages
    _sqlite_events(engine, pragmas)
    return engine


def _reader_engine(url: str) -> sa.Engine:
    """An engine that cannot write: SQLite opened ``mode=ro`` (no journal mode set, nothing made)."""
    import sqlite3
    from urllib.parse import quote

    path = sqlite_path(url)
    if path is None:
        return _server_engine(url)
    if not path.is_file():
        what = "a folder without catalogue.sqlite" if path.is_dir() else "nothing there"
        raise NoCatalogue(
            f"no catalogue at {path} ({what}): give --catalogue PATH of one; "
            "a command that writes (record, identify, `tankdaq catalogue index FOLDER`) makes one"
        )
    uri = f"file:{quote(str(path))}?mode=ro"

    def connect() -> sqlite3.Connection:
        return sqlite3.connect(uri, uri=True, timeout=BUSY_TIMEOUT_MS / 1000, check_same_thread=False)

    engine = sa.create_engine("sqlite://", creator=connect, poolclass=sa.pool.NullPool)
    _sqlite_events(engine, [])
    return engine


#: What a PostgreSQL catalogue needs installed (psycopg 3, the ``postgres`` extra), as the line says it.
POSTGRES_EXTRA = install_hint("postgres")


def _server_engine(url: str) -> sa.Engine:
    """A server's engine that gives up connecting after ``CONNECT_TIMEOUT_S`` (unless the URL says).
    Without its driver (the ``postgres`` extra) the line names the install, not "No module named"."""
    given = sa.make_url(url).query
    timeout = {} if "connect_timeout" in given else {"connect_timeout": CONNECT_TIMEOUT_S}
    try:
        return sa.create_engine(url, pool_pre_ping=True, connect_args=timeout)
    except ImportError as exc:
        raise CatalogueError(
            f"catalogue {describe(url)} not usable: PostgreSQL's driver psycopg is not installed here "
            f"({one_line(exc)}): {POSTGRES_EXTRA}"
        ) from None


def _sqlite_events(engine: sa.Engine, pragmas: list[str]) -> None:
    """Every connection: a busy timeout and ``pragmas``; a writer's BEGIN IMMEDIATE, a reader's BEGIN."""

    @sa.event.listens_for(engine, "connect")
    def _pragmas(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None  # BEGIN IMMEDIATE below, not pysqlite's deferred BEGIN
        cursor = dbapi_connection.cursor()
        cursor.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        for pragma in pragmas:
            cursor.execute(pragma)
        cursor.close()

    @sa.event.listens_for(engine, "begin")
    def _begin(connection: sa.Connection) -> None:
        if connection.get_execution_options().get(READ_ONLY):
            connection.exec_driver_sql("BEGIN")
        else:
            connection.exec_driver_sql("BEGIN IMMEDIATE")  # the write lock first: no deadlock on upgrade


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (database drivers print several)."""
    text = str(getattr(exc, "orig", None) or exc)
    return " ".join(text.split())[:300]
