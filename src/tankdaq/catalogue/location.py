"""Where the catalogue lives: ``--catalogue`` / ``TANKDAQ_CATALOGUE`` made a URL, and shown without secrets.

A URL is parsed here, by tankdaq, before SQLAlchemy sees it: so its password is known and masked in every
message (``describe``, ``scrub``), even for a URL SQLAlchemy could not parse at all, whose own message
would quote it whole. Every form a lab types is accepted (``postgres://``, ``postgresql://``, a driver
suffix, ``password=`` in the query, a password holding ``@`` or ``:``); a bad port, host or path is one
line, never a traceback.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import parse_qsl, unquote

import sqlalchemy as sa

from ..errors import InputError, TankdaqError

#: The environment variable that names the catalogue (a URL, a path, or ``none``).
ENV_VAR = "TANKDAQ_CATALOGUE"
#: The default file name, in the user data folder (platformdirs) or in a folder given as a path.
FILE_NAME = "catalogue.sqlite"
OFF = ("none", "off", "")
#: The driver every PostgreSQL form is served by (psycopg 3), and the forms taken for it.
POSTGRES = "postgresql+psycopg"
POSTGRES_FORMS = ("postgres", "postgresql", "postgresql+psycopg", "postgresql+psycopg2")
#: Query keys whose value is a secret (libpq's ``password``, and what people type for it).
SECRET_KEYS = ("password", "passwd", "pwd")
MASK = "***"
USAGE = "give a path, sqlite:///FILE or postgresql://USER@HOST/DB, or none"


class CatalogueError(TankdaqError):
    """The catalogue cannot be opened or written (locked, corrupt, unreachable): the files are unaffected."""


class BadCatalogueQuery(CatalogueError, InputError):
    """A ``--where``, ``--runs`` or filter the catalogue does not understand."""

    exit_code = 2


class NoCatalogue(BadCatalogueQuery):
    """A read named a catalogue that is not there (a typo'd path, nothing recorded yet): never made."""


@dataclass(frozen=True)
class UrlParts:
    """A server URL as typed, split by tankdaq (the password kept apart, so it is never shown)."""

    scheme: str
    user: str
    password: str
    netloc: str  # host[:port], as typed
    database: str
    query: str

    @property
    def secrets(self) -> list[str]:
        """Every text that must never be shown: the password, raw and decoded, and ``password=`` values."""
        found = [self.password] + [v for k, v in parse_qsl(self.query) if k.lower() in SECRET_KEYS]
        found += [value for key, value in _raw_query(self.query) if key.lower() in SECRET_KEYS]
        found += [unquote(value) for value in found]
        return sorted({value for value in found if value}, key=len, reverse=True)

    def masked(self) -> str:
        user = self.user + (":" + MASK if self.password else "")
        where = f"{user}@{self.netloc}" if user else self.netloc
        query = "&".join(
            f"{key}={MASK}" if key.lower() in SECRET_KEYS else f"{key}={value}"
            for key, value in _raw_query(self.query)
        )
        return f"{self.scheme}://{where}/{self.database}" + (f"?{query}" if query else "")


def _raw_query(query: str) -> list[tuple[str, str]]:
    return [(word.partition("=")[0], word.partition("=")[2]) for word in query.split("&") if word]


#: Where a URL's query starts: ``?key=`` (a ``?`` inside a password is not followed by ``key=``).
_QUERY = re.compile(r"\?[A-Za-z_]+=")


def split_url(text: str) -> UrlParts:
    """``scheme://user:password@host:port/db?query`` split without SQLAlchemy. The password ends at the
    last ``@`` before the query (``?key=``), so it may hold ``@``, ``:`` and even ``/``."""
    scheme, _, rest = text.partition("://")
    query_mark = _QUERY.search(rest)
    at = rest.rfind("@", 0, query_mark.start() if query_mark else len(rest))
    userinfo, hostpart = (rest[:at], rest[at + 1 :]) if at >= 0 else ("", rest)
    user, _, password = userinfo.partition(":")
    hostpart, _, query = hostpart.partition("?")
    netloc, _, database = hostpart.partition("/")
    return UrlParts(scheme, user, password, netloc, database, query)


def describe(url: str) -> str:
    """The URL as a person reads it: no password, whatever its form (even one nothing could parse)."""
    if "://" not in url:
        return url
    parts = split_url(url)
    if parts.scheme.lower() == "sqlite":
        return url
    return parts.masked()


def scrub(text: str, url: str | None) -> str:
    """``text`` (a driver's message) with every secret of ``url`` masked."""
    if url and "://" in url:
        for secret in split_url(url).secrets:
            text = text.replace(secret, MASK)
    return text


def resolve_url(given: str | None = None) -> str | None:
    """The catalogue's SQLAlchemy URL from ``--catalogue`` (else ``TANKDAQ_CATALOGUE``, else the user
    data folder); None when switched off (``none``). A path is a SQLite file (a folder: its own
    ``catalogue.sqlite``); every PostgreSQL form is served by psycopg 3 (``POSTGRES_FORMS``)."""
    value = os.environ.get(ENV_VAR) if given is None else given
    if isinstance(value, os.PathLike):  # tankdaq.runs(catalogue=Path(...))
        value = os.fspath(value)
    if value is not None and not isinstance(value, str):
        raise BadCatalogueQuery(f"catalogue {type(value).__name__}: {USAGE}")
    if value is not None and value.strip().lower() in OFF:
        return None
    if value is None:
        import platformdirs

        default = Path(platformdirs.user_data_dir("tankdaq")) / FILE_NAME
        return sqlite_url(_file(str(default), str(default)))
    value = value.strip()
    if "://" in value:
        return _server_url(value)
    return sqlite_url(_file(value, value))


def _server_url(text: str) -> str:
    parts = split_url(text)
    scheme = parts.scheme.lower()
    if scheme == "sqlite":
        if not parts.database and not parts.netloc:
            raise BadCatalogueQuery(f"catalogue {text!r}: an in-memory catalogue keeps nothing; {USAGE}")
        return sqlite_url(_file(text.split("://", 1)[1].removeprefix("/"), text))
    if scheme not in POSTGRES_FORMS:
        raise BadCatalogueQuery(f"catalogue {parts.masked()!r}: {USAGE}")
    host, port = _host_port(parts)
    try:
        url = sa.URL.create(
            POSTGRES,
            username=unquote(parts.user) or None,
            password=unquote(parts.password) or None,
            host=host or None,
            port=port,
            database=unquote(parts.database) or None,
            query=dict(parse_qsl(parts.query, keep_blank_values=True)),
        )
    except (ValueError, TypeError, sa.exc.ArgumentError) as exc:
        raise BadCatalogueQuery(f"catalogue {parts.masked()!r}: {scrub(str(exc), text)}") from None
    return url.render_as_string(hide_password=False)


_PORT = re.compile(r"^\d{1,5}$")


def _host_port(parts: UrlParts) -> tuple[str, int | None]:
    """The host and port of ``parts``: ``host``, ``host:5432``, ``[::1]:5432``; anything else one line."""
    netloc, where = parts.netloc, f"catalogue {parts.masked()!r}"
    if netloc.startswith("["):
        host, bracket, port_text = netloc[1:].partition("]")
        if not bracket or (port_text and not port_text.startswith(":")):
            raise BadCatalogueQuery(f"{where}: write an IPv6 host in brackets, [::1] or [::1]:5432")
        port_text = port_text[1:]
    else:
        host, _, port_text = netloc.partition(":")
    if any(c in host for c in "[]/@?#, "):
        raise BadCatalogueQuery(f"{where}: host {host!r} not understood; {USAGE}")
    if not port_text and not netloc.endswith(":"):
        return host, None
    if not _PORT.match(port_text) or not 0 < int(port_text) < 65536:
        raise BadCatalogueQuery(f"{where}: port {port_text!r} is not a number from 1 to 65535")
    return host, int(port_text)


def _file(text: str, given: str) -> Path:
    """A path typed for a SQLite catalogue (a folder: its ``catalogue.sqlite``), resolved; a home
    that does not exist or a name too long for the file system is one line."""
    try:
        path = Path(text).expanduser()
        return (path / FILE_NAME if path.is_dir() else path).resolve()
    except (RuntimeError, OSError, ValueError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise BadCatalogueQuery(f"catalogue path {given!r}: {why}") from None


def sqlite_url(path: Path) -> str:
    return f"sqlite:///{path}"


def sqlite_path(url: str) -> Path | None:
    """The file of a SQLite URL (None: another backend)."""
    scheme, _, rest = url.partition("://")
    return Path(rest.removeprefix("/")) if scheme.lower() == "sqlite" else None
