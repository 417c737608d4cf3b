"""Where the catalogue lives and what its tables are: one URL, one schema, migrations of its own.

The catalogue is an index of files, never their only copy: every row can be rebuilt from the files
(``catalogue.index``). So the schema is migrated by ordered functions recorded in a ``schema_version``
table (lighter than Alembic for six tables), and a catalogue that cannot be opened is one line
(``CatalogueError``), never a lost recording.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any, TypeVar

import sqlalchemy as sa

from ..errors import InputError, TankdaqError
from ..records import DecayEnd

T = TypeVar("T")

#: The environment variable that names the catalogue (a URL, a path, or ``none``).
ENV_VAR = "TANKDAQ_CATALOGUE"
#: The default file name, in the user data folder (platformdirs) or in a folder given as a path.
FILE_NAME = "catalogue.sqlite"
#: How long a writer waits for another one's lock before giving up (SQLite), in ms.
BUSY_TIMEOUT_MS = 30_000
OFF = ("none", "off", "")
#: The execution option that marks a connection as a reader (``Catalogue.reading``).
READ_ONLY = "tankdaq_read_only"
#: How many values one look-up asks for (a bound parameter list, well under every driver's limit).
LOOKUP_BATCH = 500


def in_batches(values: Sequence[T]) -> Iterator[Sequence[T]]:
    """``values`` in slices of at most ``LOOKUP_BATCH``: one look-up's ``IN`` list each."""
    for start in range(0, len(values), LOOKUP_BATCH):
        yield values[start : start + LOOKUP_BATCH]


class CatalogueError(TankdaqError):
    """The catalogue cannot be opened or written (locked, corrupt, unreachable): the files are unaffected."""


class BadCatalogueQuery(CatalogueError, InputError):
    """A ``--where``, ``--runs`` or filter the catalogue does not understand."""

    exit_code = 2


metadata = sa.MetaData()

schema_version = sa.Table(
    "schema_version",
    metadata,
    sa.Column("version", sa.Integer, primary_key=True),
    sa.Column("applied_utc", sa.String(40), nullable=False),
)

hulls = sa.Table(
    "hulls",
    metadata,
    sa.Column("sha256", sa.String(64), primary_key=True),  # a changed GM is a new version, never an edit
    sa.Column("name", sa.String(64), nullable=False, index=True),
    sa.Column("path", sa.Text, nullable=False),
    sa.Column("content", sa.Text, nullable=False),
    sa.Column("first_seen_utc", sa.String(40), nullable=False),
)

sessions = sa.Table(
    "sessions",
    metadata,
    sa.Column("session_id", sa.String(64), primary_key=True),  # hash of the log's first record
    sa.Column("folder", sa.Text, nullable=False),
    sa.Column("plan", sa.String(128)),
    sa.Column("hull", sa.String(64)),
    sa.Column("started_utc", sa.String(40)),
    sa.Column("decays", sa.Integer, nullable=False, default=0),
    sa.Column("accepted", sa.Integer, nullable=False, default=0),
    sa.Column("updated_utc", sa.String(40), nullable=False),
)

decays = sa.Table(
    "decays",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("sha256", sa.String(64), nullable=False, unique=True),
    sa.Column("path", sa.Text, nullable=False),
    sa.Column("size_bytes", sa.BigInteger, nullable=False),
    sa.Column("complete", sa.Boolean, nullable=False),
    sa.Column("recorded_utc", sa.String(40), index=True),
    # the condition
    sa.Column("hull", sa.String(64), index=True),
    sa.Column("hull_sha256", sa.String(64)),
    sa.Column("draft", sa.String(16), index=True),
    sa.Column("axis", sa.String(8), index=True),
    sa.Column("speed_m_s", sa.Float),
    sa.Column("angle_nominal_deg", sa.Float),
    sa.Column("release_angle_deg", sa.Float),
    # the device
    sa.Column("device_id", sa.String(32)),
    sa.Column("firmware", sa.String(32)),
    # the session and the operator's word
    sa.Column("session_id", sa.String(64), index=True),
    sa.Column("plan", sa.String(128)),
    sa.Column("decay_number", sa.Integer),
    sa.Column("verdict", sa.String(16), index=True),
    sa.Column("checks", sa.JSON),  # the reasons a check gave, one line each
    # the reference fit (``fits``: every fit is kept; these columns copy the one the lab's number is)
    sa.Column("fit_source", sa.String(16)),
    sa.Column("fit_model", sa.Text),
    sa.Column("coefficients", sa.JSON),  # {term: {"value", "ci_low", "ci_high"}}
    sa.Column("natural_period_s", sa.Float),
    sa.Column("b_eq_per_s", sa.JSON),  # {"2": B_eq/I at 2 deg, "5": ..., "10": ...}
    sa.Column("b44_hat", sa.JSON),  # the same amplitudes, where the hull gives beam and displacement
    sa.Column("r2_angle", sa.Float),
    sa.Column("warnings", sa.JSON),
    sa.Column("code_version", sa.String(32)),
    sa.Column("created_utc", sa.String(40), nullable=False),
    sa.Column("updated_utc", sa.String(40), nullable=False),
    # version 4: how the decay ended, its reference fit, and a row whose path now holds other bytes
    sa.Column("ended", sa.String(16)),  # records.DecayEnd; None: not said (a lab's file)
    sa.Column("fit_method", sa.String(32)),
    sa.Column("reference_fit_id", sa.Integer),
    sa.Column("reference_chosen", sa.Boolean),  # True: set by the lab (--set-reference), never by a rule
    sa.Column("retired_utc", sa.String(40)),  # its path holds other bytes now: kept, never listed
)


#: A file exported from a recording (``tankdaq export``: HDF5 per decay, CSV with its sidecar): kept
#: apart from ``decays``, tied to its recording's row, so a query never lists a decay twice.
exports = sa.Table(
    "exports",
    metadata,
    sa.Column("sha256", sa.String(64), primary_key=True),
    sa.Column("path", sa.Text, nullable=False),
    sa.Column("size_bytes", sa.BigInteger, nullable=False),
    sa.Column("format", sa.String(16), nullable=False),  # the suffix: h5, csv
    sa.Column("source_path", sa.Text),  # the recording it was exported from, as the export says
    sa.Column("source_sha256", sa.String(64), index=True),  # that recording's row, when it is known
    sa.Column("decay", sa.Integer),  # which of the recording's decays (HDF5: one file per decay)
    sa.Column("created_utc", sa.String(40), nullable=False),
    sa.Column("updated_utc", sa.String(40), nullable=False),
)


class FitSource(StrEnum):
    """Which command made a fit."""

    RECORD = "record"  #: the live final fit the recorder stored in the file
    SESSION = "session"  #: that fit, of a decay a guided session's operator accepted
    IDENTIFY = "identify"
    IDENTIFY_JOINT = "identify-joint"  #: a ``--joint`` fit of several conditions, on each one's rows
    CAMPAIGN = "campaign"  #: a campaign group's joint fit of its repeats
    DIAGNOSE = "diagnose"


class FitMethod(StrEnum):
    """How a fit was made (the estimator)."""

    OUTPUT_ERROR = "output-error"
    EQUATION_ERROR = "equation-error"
    GA = "ga"
    PSO = "pso"
    LIVE = "live"  #: the recorder's online fit
    OTHER = "other"  #: an estimator registered by a user (its name in the fit's settings)
    UNKNOWN = "unknown"  #: a fit catalogued before fits were kept (schema version 4)

    @classmethod
    def of_option(cls, method: str) -> FitMethod:
        """The method ``--method`` names: ``oe``, ``ee``, ``ga``, ``pso`` and the seeds' ``ga-seed000``."""
        name = method.strip().lower()
        named = {"oe": cls.OUTPUT_ERROR, "ee": cls.EQUATION_ERROR}
        if name in named:
            return named[name]
        for family in (cls.GA, cls.PSO):
            if name == family or name.startswith(f"{family}-"):
                return family
        return cls.OTHER


#: What a decay row copies from its reference fit: fit column -> decay column.
REFERENCE_COPY = {
    "source": "fit_source",
    "method": "fit_method",
    "model": "fit_model",
    "coefficients": "coefficients",
    "natural_period_s": "natural_period_s",
    "b_eq_per_s": "b_eq_per_s",
    "b44_hat": "b44_hat",
    "r2_angle": "r2_angle",
    "warnings": "warnings",
}


#: Every fit of a decay, kept (version 4): what was fitted (the bytes' SHA-256), how (source: the
#: command; method: the estimator), the model, the numbers, and who, where, when and with which command.
fits = sa.Table(
    "fits",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("decay_id", sa.Integer, nullable=False, index=True),
    sa.Column("sha256", sa.String(64), nullable=False, index=True),  # the bytes the fit read
    sa.Column("path", sa.Text, nullable=False),
    sa.Column("source", sa.String(16), nullable=False),  # catalogue.fits.FitSource
    sa.Column("method", sa.String(32), nullable=False),  # catalogue.fits.FitMethod
    sa.Column("model", sa.Text),
    sa.Column("terms", sa.JSON),
    sa.Column("model_by_data", sa.Boolean, nullable=False),  # chosen by the data (``auto``), not named
    sa.Column("coefficients", sa.JSON),
    sa.Column("natural_period_s", sa.Float),
    sa.Column("b_eq_per_s", sa.JSON),
    sa.Column("b44_hat", sa.JSON),
    sa.Column("r2_angle", sa.Float),
    sa.Column("warnings", sa.JSON),
    sa.Column("settings", sa.JSON),
    sa.Column("software_version", sa.String(32)),
    sa.Column("host", sa.String(255)),
    sa.Column("user_name", sa.String(255)),
    sa.Column("command", sa.Text),
    sa.Column("created_utc", sa.String(40), nullable=False),
)


#: A fit is written onto its files' rows by path (identify, campaign, diagnose), and a campaign asks
#: which of its files have a row: by an index, not a scan of every row (10 ms an update at 36 000 rows).
PATH_INDEXES = (
    sa.Index("ix_decays_path", decays.c.path),
    sa.Index("ix_exports_source_path", exports.c.source_path),
)


def _v1_tables(connection: sa.Connection) -> None:
    for table in (hulls, sessions, decays):
        table.create(connection, checkfirst=True)


def _v2_exports(connection: sa.Connection) -> None:
    exports.create(connection, checkfirst=True)


def _v3_path_indexes(connection: sa.Connection) -> None:
    for index in PATH_INDEXES:
        index.create(connection, checkfirst=True)


def _v4_fits(connection: sa.Connection) -> None:
    """The ``fits`` table and the decay columns of version 4; each older row's one fit becomes its first
    kept fit and its reference, and a row of a file without its footer ended ``cut``."""
    present = {column["name"] for column in sa.inspect(connection).get_columns("decays")}
    for column in decays.columns:
        if column.name not in present:
            kind = column.type.compile(connection.dialect)
            connection.exec_driver_sql(f"ALTER TABLE decays ADD COLUMN {column.name} {kind}")
    fits.create(connection, checkfirst=True)
    _migrate_fits(connection)


def _migrate_fits(connection: sa.Connection) -> None:
    """Version 4 over an older catalogue: each row's one fit kept as its first (method unknown) and made
    its reference; a row of a file without its footer ended ``cut``."""
    connection.execute(decays.update().where(decays.c.complete.is_(False)).values(ended=DecayEnd.CUT.value))
    columns = [decays.c.id, decays.c.sha256, decays.c.path, decays.c.updated_utc]
    columns += [decays.c[column] for column in REFERENCE_COPY.values() if column not in ("fit_method",)]
    olds = connection.execute(sa.select(*columns).where(decays.c.fit_source.is_not(None))).all()
    for old in olds:
        values = {
            name: getattr(old, column) for name, column in REFERENCE_COPY.items() if column != "fit_method"
        }
        values |= {"method": FitMethod.UNKNOWN.value, "model_by_data": False, "created_utc": old.updated_utc}
        fit_id = connection.execute(
            fits.insert().values(decay_id=old.id, sha256=old.sha256, path=old.path, **values)
        ).inserted_primary_key[0]  # type: ignore[index]
        connection.execute(
            decays.update()
            .where(decays.c.id == old.id)
            .values(reference_fit_id=fit_id, reference_chosen=False, fit_method=FitMethod.UNKNOWN.value)
        )


#: Ordered migrations: index i brings the schema to version i + 1. Append, never edit.
MIGRATIONS: list[Callable[[sa.Connection], None]] = [_v1_tables, _v2_exports, _v3_path_indexes, _v4_fits]
SCHEMA_VERSION = len(MIGRATIONS)


def resolve_url(given: str | None = None) -> str | None:
    """The catalogue's SQLAlchemy URL from ``--catalogue`` (else ``TANKDAQ_CATALOGUE``, else the user
    data folder); None when switched off (``none``). A path is a SQLite file (a folder: its own
    ``catalogue.sqlite``); ``postgresql://`` is served by psycopg 3."""
    value = os.environ.get(ENV_VAR) if given is None else given
    if value is not None and value.strip().lower() in OFF:
        return None
    if value is None:
        import platformdirs

        return _sqlite_url(Path(platformdirs.user_data_dir("tankdaq")) / FILE_NAME)
    value = value.strip()
    if value.startswith("postgresql://"):
        return "postgresql+psycopg://" + value.removeprefix("postgresql://")
    if "://" in value:
        if not value.startswith(("sqlite://", "postgresql+psycopg://")):
            raise BadCatalogueQuery(
                f"catalogue {value!r}: give a path, sqlite:///FILE or postgresql://USER@HOST/DB, or none"
            )
        return value
    path = Path(value).expanduser()
    return _sqlite_url(path / FILE_NAME if path.is_dir() else path)


def _sqlite_url(path: Path) -> str:
    return f"sqlite:///{path.resolve()}"


def describe(url: str) -> str:
    """The URL as a person reads it (no password)."""
    return sa.make_url(url).render_as_string(hide_password=True)


@dataclass
class Catalogue:
    """An open catalogue: ``engine`` and the URL it came from (``open_catalogue``)."""

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

    def __exit__(self, *exc: object) -> None:
        self.close()


#: SQLite's page cache for a recorder's catalogue writer: it appends a row a decay, so a small cache
#: costs it nothing, while SQLite's own 2 MB filled over a lab day (+1.5 MB of a recorder's 8-hour
#: growth, bench_memory_day; the pages stay in the system's file cache).
WRITER_CACHE_KB = 256


def open_catalogue(url: str, cache_kb: int | None = None) -> Catalogue:
    """Connect, create or migrate the schema; SQLite in WAL mode with a busy timeout, so several
    recorders and an analysis write at once. Whatever fails is one ``CatalogueError`` line.
    ``cache_kb``: SQLite's page cache per connection (None: SQLite's own, 2 MB; ``WRITER_CACHE_KB``)."""
    try:
        engine = _engine(url, cache_kb)
        with engine.begin() as connection:
            migrate(connection)
    except CatalogueError:
        raise
    except (sa.exc.SQLAlchemyError, OSError, ImportError) as exc:
        raise CatalogueError(f"catalogue {describe(url)} not usable: {one_line(exc)}") from None
    return Catalogue(url, engine)


def _engine(url: str, cache_kb: int | None) -> sa.Engine:
    parsed = sa.make_url(url)
    if parsed.get_backend_name() != "sqlite":
        return sa.create_engine(url, pool_pre_ping=True)
    if parsed.database:
        Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
    engine = sa.create_engine(url, connect_args={"timeout": BUSY_TIMEOUT_MS / 1000})

    @sa.event.listens_for(engine, "connect")
    def _pragmas(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None  # BEGIN IMMEDIATE below, not pysqlite's deferred BEGIN
        cursor = dbapi_connection.cursor()
        cursor.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        cursor.execute("PRAGMA journal_mode = WAL")
        cursor.execute("PRAGMA synchronous = NORMAL")
        if cache_kb is not None:
            cursor.execute(f"PRAGMA cache_size = {-int(cache_kb)}")  # negative: KiB, not pages
        cursor.close()

    @sa.event.listens_for(engine, "begin")
    def _begin(connection: sa.Connection) -> None:
        if connection.get_execution_options().get(READ_ONLY):
            connection.exec_driver_sql("BEGIN")
        else:
            connection.exec_driver_sql("BEGIN IMMEDIATE")  # the write lock first: no deadlock on upgrade

    return engine


def utc_now() -> str:
    """Now, as every catalogue time is written (UTC, ISO 8601, to the millisecond)."""
    from datetime import UTC, datetime

    return datetime.now(UTC).isoformat(timespec="milliseconds")


def migrate(connection: sa.Connection) -> int:
    """Bring the schema to ``SCHEMA_VERSION``; returns the version found. A newer catalogue (written by
    a later tankdaq) is refused rather than written with the wrong columns."""
    from datetime import UTC, datetime

    if connection.dialect.name == "postgresql":  # two processes opening a new catalogue at once
        connection.execute(sa.text("SELECT pg_advisory_xact_lock(24240424)"))
    schema_version.create(connection, checkfirst=True)
    found = connection.execute(sa.select(sa.func.max(schema_version.c.version))).scalar() or 0
    if found > SCHEMA_VERSION:
        raise CatalogueError(
            f"catalogue schema version {found} is newer than this tankdaq's ({SCHEMA_VERSION}): "
            "upgrade tankdaq"
        )
    for version in range(found + 1, SCHEMA_VERSION + 1):
        MIGRATIONS[version - 1](connection)
        now = datetime.now(UTC).isoformat(timespec="seconds")
        connection.execute(schema_version.insert().values(version=version, applied_utc=now))
    return int(found)


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (database drivers print several)."""
    text = str(getattr(exc, "orig", None) or exc)
    return " ".join(text.split())[:300]
