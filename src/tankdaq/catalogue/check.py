"""``tankdaq catalogue check URL``: can this PC use that catalogue? Whether it connects (and why not, its
password masked), its schema version against this tankdaq's, and how many rows its main tables hold.

A lab sets up its server once and then points every PC at it; this is the one command that says whether a
PC got there, so it only reads: nothing is made, migrated or written, even on an empty database.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sqlalchemy as sa

from .database import OPEN_FAILURES, Catalogue, _reader_engine, check_schema, failure
from .location import BadCatalogueQuery, CatalogueError, describe, resolve_url
from .schema import SCHEMA_VERSION

#: The tables whose rows are counted, in the order shown (any a catalogue does not have yet is left out).
COUNTED = ("decays", "fits", "sessions", "hulls", "exports", "budgets")


@dataclass(frozen=True)
class CatalogueCheck:
    """What ``check_catalogue`` found. ``reason``: why it is not usable (None: it is); ``version`` 0 is a
    database without tables yet (a writer makes the catalogue there)."""

    where: str  # the URL without its password
    reason: str | None = None
    server: str = ""  # e.g. "PostgreSQL 16.4"
    version: int = 0
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def usable(self) -> bool:
        return self.reason is None

    def lines(self) -> list[str]:
        """What ``tankdaq catalogue check`` prints of a usable catalogue."""
        if self.version == 0:
            state = "no catalogue yet: the first command that writes (record, identify, index) makes it"
        elif self.version < SCHEMA_VERSION:
            state = (
                "older: the next command that writes (or `catalogue index`) migrates it; reads wait for that"
            )
        else:
            state = "this tankdaq reads and writes it"
        rows = ", ".join(f"{name} {count}" for name, count in self.counts.items()) or "none"
        return [
            f"catalogue {self.where}: connected ({self.server})",
            f"schema version {self.version} (this tankdaq's: {SCHEMA_VERSION}): {state}",
            f"rows: {rows}",
        ]


def check_catalogue(given: str | None) -> CatalogueCheck:
    """Connect to the catalogue ``given`` names (as ``--catalogue``: a URL, a path, None for
    ``TANKDAQ_CATALOGUE``) and read what it is; never writes. A URL that cannot be a catalogue is
    ``BadCatalogueQuery`` (usage); every other failure is the result's ``reason``, one line."""
    url = resolve_url(given)
    if url is None:
        raise BadCatalogueQuery("the catalogue is switched off (none): give a URL or path to check")
    where = describe(url)
    try:
        with Catalogue(url, _reader_engine(url)) as opened, opened.reading() as connection:
            with connection.begin():
                version = check_schema(connection, url, writing=True)
                present = set(sa.inspect(connection).get_table_names())
                counts = {
                    name: int(
                        connection.execute(
                            sa.select(sa.func.count()).select_from(sa.table(name))
                        ).scalar_one()
                    )
                    for name in COUNTED
                    if name in present
                }
            server = _server(connection)
    except CatalogueError as exc:
        return CatalogueCheck(where, reason=str(exc))
    except OPEN_FAILURES as exc:
        return CatalogueCheck(where, reason=str(failure(url, exc)))
    return CatalogueCheck(where, server=server, version=version, counts=counts)


def _server(connection: sa.Connection) -> str:
    """The database software and its version, as the driver reports it."""
    dialect = connection.dialect
    name = {"postgresql": "PostgreSQL", "sqlite": "SQLite"}.get(dialect.name, dialect.name)
    version = ".".join(str(part) for part in dialect.server_version_info or ())
    return f"{name} {version}".strip()
