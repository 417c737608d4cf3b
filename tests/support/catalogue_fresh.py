"""A fresh, empty catalogue location per test: a SQLite path in the test's folder, or a database of its
own on the module's throwaway PostgreSQL server (tests/support/pg_server.py), dropped after the test. So every
test of a module may use the real server, not only one."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa

from tankdaq.catalogue.database import resolve_url


def fresh_catalogue(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """For a fixture parametrized ``sqlite``/``postgresql``: where the test's catalogue is to be (not
    made: a reader must find nothing there)."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
        return
    server = str(request.getfixturevalue("postgres_url"))
    name = f"t{uuid.uuid4().hex[:12]}"
    admin = sa.create_engine(str(resolve_url(server)), isolation_level="AUTOCOMMIT")
    try:
        with admin.connect() as connection:
            connection.exec_driver_sql(f'CREATE DATABASE "{name}"')
        yield f"{server.rsplit('/', 1)[0]}/{name}"
        with admin.connect() as connection:
            connection.exec_driver_sql(f'DROP DATABASE "{name}" WITH (FORCE)')
    finally:
        admin.dispose()


def table_names(url: str) -> list[str]:
    """The tables of the database at ``url``, read with SQLAlchemy's own inspector."""
    engine = sa.create_engine(str(resolve_url(url)))
    try:
        return sorted(sa.inspect(engine).get_table_names())
    finally:
        engine.dispose()
