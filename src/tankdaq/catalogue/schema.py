"""What the catalogue's tables are, and the ordered migrations that bring any catalogue to them.

The catalogue is an index of files, never their only copy: every row can be rebuilt from the files
(``catalogue.index``). So the schema is migrated by ordered functions recorded in a ``schema_version``
table (lighter than Alembic for six tables). The fit vocabulary (``FitSource``, ``FitMethod``) lives with
the ``fits`` table it describes.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum

import sqlalchemy as sa

from ..records import DecayEnd
from .location import CatalogueError

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
    # ``_release_interval``: the release instant on the device clock and its 95 % half-width (None: unknown)
    sa.Column("release_t_s", sa.Float),
    sa.Column("release_u95_s", sa.Float),
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


#: Each kept fit's uncertainty budget (``ident.budget``): one row per reported quantity and source, with
#: the quantity's combined standard uncertainty and expanded U (coverage factor k).
budgets = sa.Table(
    "budgets",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("fit_id", sa.Integer, nullable=False, index=True),
    sa.Column("quantity", sa.Text, nullable=False),
    sa.Column("quantity_key", sa.String(64), nullable=False),
    sa.Column("unit", sa.String(32)),
    sa.Column("value", sa.Float),
    sa.Column("source", sa.Text, nullable=False),
    sa.Column("kind", sa.String(1), nullable=False),  # GUM's Type A or B
    sa.Column("u", sa.Float),
    sa.Column("u_unit", sa.String(32)),
    sa.Column("sensitivity", sa.Float),
    sa.Column("contribution", sa.Float),
    sa.Column("share", sa.Float),
    sa.Column("combined_u", sa.Float),
    sa.Column("expanded_u", sa.Float),
    sa.Column("coverage_factor", sa.Float),
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
    _add_decay_columns(connection)
    fits.create(connection, checkfirst=True)
    _migrate_fits(connection)


def _add_decay_columns(connection: sa.Connection) -> None:
    """The ``decays`` columns an older catalogue lacks, added empty (its rows: not known)."""
    present = {column["name"] for column in sa.inspect(connection).get_columns("decays")}
    for column in decays.columns:
        if column.name not in present:
            kind = column.type.compile(connection.dialect)
            connection.exec_driver_sql(f"ALTER TABLE decays ADD COLUMN {column.name} {kind}")


def _release_interval(connection: sa.Connection) -> None:
    """The release instant and its 95 % half-width: empty (unknown) on the rows already there; ``index``
    of a new file fills them from its release event."""
    _add_decay_columns(connection)


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


def _budgets_table(connection: sa.Connection) -> None:
    """The ``budgets`` table (each fit's uncertainty budget); fits kept before it have none."""
    budgets.create(connection, checkfirst=True)


#: Ordered migrations: index i brings the schema to version i + 1. Append, never edit.
MIGRATIONS: list[Callable[[sa.Connection], None]] = [
    _v1_tables, _v2_exports, _v3_path_indexes, _v4_fits, _release_interval, _budgets_table,
]  # fmt: skip
SCHEMA_VERSION = len(MIGRATIONS)


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
