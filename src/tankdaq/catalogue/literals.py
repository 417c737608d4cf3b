"""What a query types, read strictly: dates, numbers and quoted words (``catalogue.query`` builds on it).

A filter that is read wrongly answers wrongly without a word (a date with a space compared as text, a
number SQLite cannot hold, ``NaN``, an unclosed quote): so each is read here as what it means, or refused
in one line that shows the right way to write it. Times are UTC, as the catalogue stores them.
"""

from __future__ import annotations

import math
import re
from datetime import UTC, datetime, timedelta, timezone
from typing import Any

import sqlalchemy as sa

from .location import BadCatalogueQuery

#: How many ``and`` clauses one ``--where`` may hold (SQLite's expression depth is 1000).
MAX_CLAUSES = 100
#: The largest whole number each integer column holds (PostgreSQL's INTEGER and BIGINT, SQLite's 8 bytes).
INTEGER_LIMITS = {sa.BigInteger: 2**63 - 1, sa.Integer: 2**31 - 1}
DATE_HELP = (
    "write 2026, 2026-03, 2026-03-15, 2026-03-15 14:30 or 2026-03-15T14:30:05 (UTC; "
    "a zone such as +01:00, or `local` for this PC's time, after a time)"
)
_DATE = re.compile(
    r"^(?P<year>\d{4})(?:-(?P<month>\d{2})(?:-(?P<day>\d{2})"
    r"(?:[T ](?P<hour>\d{2}):(?P<minute>\d{2})(?::(?P<second>\d{2})(?:\.(?P<fraction>\d{1,3}))?)?)?)?)?"
    r"\s*(?P<zone>Z|UTC|[+-]\d{2}:?\d{2}|local)?$",
    re.IGNORECASE,
)
#: The pieces of a ``--where``: a quoted value, a lone quote (unclosed), the ``and`` between clauses.
_SLIP = re.compile(r"^\s*([a-z_0-9]+)\s*([=<>!~][=<>!~\s]*[=<>!~]|[=<>!~])(.*)$", re.IGNORECASE)
_TOKEN = re.compile(r"\"[^\"]*\"|'[^']*'|[\"']|\s+and\s+|[^\"'\s]+|\s+", re.IGNORECASE)


def _text(name: str, value: object) -> str:
    """A filter is text (from Python, too: ``since=2026`` is refused by name, not an AttributeError)."""
    if not isinstance(value, str):
        raise BadCatalogueQuery(f"{name}: give text such as '2026-03' or 'swath', not {type(value).__name__}")
    return value


def parse_date(text: str) -> tuple[str, str | None]:
    """A date or time as the catalogue compares it (UTC, ISO with a ``T``: a prefix of the stored
    ``recorded_utc``), and a note when a zone or local time was converted (None: taken as UTC)."""
    found = _DATE.match(_text("date", text).strip())
    if not found:
        raise BadCatalogueQuery(f"date {text!r} not understood: {DATE_HELP}")
    parts = {k: v for k, v in found.groupdict().items() if v is not None}
    zone = parts.pop("zone", None)
    if zone and "hour" not in parts:
        raise BadCatalogueQuery(f"date {text!r}: a zone needs a time, e.g. 2026-03-15 00:00 {zone}")
    try:
        moment = datetime(
            int(parts["year"]),
            int(parts.get("month", 1)),
            int(parts.get("day", 1)),
            int(parts.get("hour", 0)),
            int(parts.get("minute", 0)),
            int(parts.get("second", 0)),
            int(parts.get("fraction", "0").ljust(6, "0")),
        )
    except ValueError as exc:
        raise BadCatalogueQuery(f"date {text!r}: {exc}; {DATE_HELP}") from None
    if zone is None or zone.upper() in ("Z", "UTC"):
        return _prefix(moment, parts), None
    utc = _to_utc(moment, zone)
    shown = f"{utc.isoformat(timespec='seconds')} UTC"
    return utc.isoformat(timespec="milliseconds" if "fraction" in parts else "seconds"), (
        f"{text.strip()} read as {shown}"
    )


def _prefix(moment: datetime, parts: dict[str, str]) -> str:
    """As much of ``moment`` as was typed: ``2026-03`` stays a month, ``14:30`` a minute."""
    if "hour" not in parts:
        return moment.isoformat()[: {"year": 4, "month": 7, "day": 10}[list(parts)[-1]]]
    spec = "milliseconds" if "fraction" in parts else "seconds" if "second" in parts else "minutes"
    return moment.isoformat(timespec=spec)


def _to_utc(moment: datetime, zone: str) -> datetime:
    if zone.lower() == "local":
        local = moment.astimezone()  # a naive time is the PC's own
    else:
        sign = -1 if zone[0] == "-" else 1
        digits = zone[1:].replace(":", "")
        offset = timedelta(hours=int(digits[:2]), minutes=int(digits[2:]))
        local = moment.replace(tzinfo=timezone(sign * offset))
    return local.astimezone(UTC).replace(tzinfo=None)


def parse_number(name: str, text: str, column_type: sa.types.TypeEngine[Any]) -> float | int:
    """A finite number the column can hold: ``NaN``, ``inf`` and ``1e30`` for an integer column are
    refused in one line, never an overflow in the driver."""
    try:
        number = float(text)
    except ValueError:
        raise BadCatalogueQuery(f"{name}: {text!r} is not a number") from None
    if not math.isfinite(number):
        raise BadCatalogueQuery(f"{name}: {text!r} is not a finite number; give one such as 0.99")
    if not isinstance(column_type, sa.Integer):
        return number
    limit = next(value for kind, value in INTEGER_LIMITS.items() if isinstance(column_type, kind))
    whole = int(text) if re.fullmatch(r"\s*[+-]?\d+\s*", text) else number  # exact, not rounded
    if abs(whole) > limit:
        raise BadCatalogueQuery(f"{name}: {text!r} is out of range (a whole number up to {limit})")
    return whole


def checked_text(name: str, text: str) -> str:
    """``text`` as a value any backend binds: no NUL (PostgreSQL refuses it), no undecodable bytes."""
    try:
        _text(name, text).encode("utf-8")
    except UnicodeEncodeError:
        raise BadCatalogueQuery(f"{name}: {text!r} holds bytes that are not text (UTF-8)") from None
    if "\x00" in text:
        raise BadCatalogueQuery(f"{name}: {text!r} holds a NUL character")
    return text


def split_clauses(text: str) -> list[str]:
    """``--where`` cut at each ``and`` outside quotes; an unclosed quote or too many clauses is one line."""
    clauses, current = [], ""
    for token in _TOKEN.findall(_text("--where", text).strip()):
        if token in ('"', "'"):
            raise BadCatalogueQuery(
                f'--where {text!r}: a quote {token} is not closed; quote a value whole: plan = "trial 2"'
            )
        if token.strip().lower() == "and":
            clauses.append(current)
            current = ""
        else:
            current += token
    clauses.append(current)
    if len(clauses) > MAX_CLAUSES:
        raise BadCatalogueQuery(
            f"--where holds {len(clauses)} clauses; at most {MAX_CLAUSES}: narrow it with --hull, "
            "--draft, --since or a ~ (contains)"
        )
    return clauses


def operator_slip(clause: str) -> str | None:
    """What to write instead of ``hull == swath`` or ``r2 => 0.9`` (None: no such slip)."""
    found = _SLIP.match(clause)
    if not found:
        return None
    name, typed, rest = found.group(1), found.group(2).replace(" ", ""), found.group(3).strip()
    if typed in ("<=", ">=", "!=", "=", "<", ">", "~"):
        return None
    if typed == "==":
        return f"write {name} = {rest} (one =)"
    if typed in ("=>", "=<"):
        return f"write {name} {typed[::-1]} {rest}"
    return f"write {name} OP {rest}, OP one of = != < <= > >= ~"
