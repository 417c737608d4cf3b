"""Asking the catalogue like a lab asks: filters, a tiny ``--where`` language, a DataFrame.

Nothing a user types reaches SQL as text: a filter or a ``--where`` clause names a known column and
an operator from a fixed list, and its value is a bound parameter. ``hull=swath draft=1.1T
since=2026-03`` (``--runs``) and ``r2 >= 0.99 and verdict = accepted`` (``--where``) are parsed here.
"""

from __future__ import annotations

import json
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa

from ..config.hulls import format_draft, parse_draft
from ..errors import InputError
from ..records import DecayEnd, Verdict
from .database import BadCatalogueQuery, Catalogue, in_batches, read_catalogue, resolve_url
from .literals import checked_text, operator_slip, parse_date, parse_number, split_clauses
from .rows import STANDARD_AMPLITUDES_DEG
from .schema import decays, exports

if TYPE_CHECKING:
    import pandas as pd

#: The names a query may use, and the column each means.
FIELDS: dict[str, sa.Column[Any]] = {
    "hull": decays.c.hull,
    "draft": decays.c.draft,
    "axis": decays.c.axis,
    "speed": decays.c.speed_m_s,
    "angle": decays.c.angle_nominal_deg,
    "release_angle": decays.c.release_angle_deg,
    "device": decays.c.device_id,
    "firmware": decays.c.firmware,
    "session": decays.c.session_id,
    "plan": decays.c.plan,
    "decay": decays.c.decay_number,
    "verdict": decays.c.verdict,
    "model": decays.c.fit_model,
    "source": decays.c.fit_source,
    "method": decays.c.fit_method,
    "ended": decays.c.ended,
    "period": decays.c.natural_period_s,
    "r2": decays.c.r2_angle,
    "complete": decays.c.complete,
    "recorded": decays.c.recorded_utc,
    "path": decays.c.path,
    "sha256": decays.c.sha256,
    "size": decays.c.size_bytes,
    "version": decays.c.code_version,
}
OPERATORS = {
    "=": lambda c, v: c == v,
    "!=": lambda c, v: c != v,
    "<": lambda c, v: c < v,
    "<=": lambda c, v: c <= v,
    ">": lambda c, v: c > v,
    ">=": lambda c, v: c >= v,
    "~": lambda c, v: c.contains(v, autoescape=True),
}
_CLAUSE = re.compile(r"^\s*([a-z_0-9]+)\s*(<=|>=|!=|=|<|>|~)\s*(\"[^\"]*\"|'[^']*'|\S+)\s*$")
#: What ``--verdict`` takes (absent: every decay not rejected; ``any``: all, rejected included).
VERDICTS = tuple(Verdict)
WHERE_HELP = "field op value [and ...]; op = != < <= > >= ~ (contains); fields: " + ", ".join(FIELDS)


@dataclass(frozen=True)
class RunQuery:
    """What to list: equality filters, a date range, and ``--where`` clauses, all checked here."""

    equal: dict[str, str] = field(default_factory=dict)
    since: str | None = None
    until: str | None = None
    where: str | None = None

    def conditions(self) -> list[sa.ColumnElement[bool]]:
        equal = dict(self.equal)
        verdict = equal.pop("verdict", None)
        found = ended_conditions(equal.pop("ended", None))
        found += [FIELDS[name] == _value(name, value) for name, value in equal.items()]
        if verdict is None:  # a rejected decay is listed only when asked for: the lab's list is the kept
            found.append(sa.or_(decays.c.verdict.is_(None), decays.c.verdict != Verdict.REJECTED.value))
        elif verdict != "any":
            if verdict not in VERDICTS:
                raise BadCatalogueQuery(f"verdict {verdict!r}: give {', '.join(VERDICTS)} or any")
            found.append(decays.c.verdict == verdict)
        if self.since:
            found.append(decays.c.recorded_utc >= _date(self.since))
        if self.until:
            found.append(decays.c.recorded_utc < _date(self.until))
        return found + (parse_where(self.where) if self.where else [])

    def notes(self) -> list[str]:
        """How the dates were read where a zone or local time was converted to UTC (one line each)."""
        dates = {"since": self.since, "until": self.until}
        return [f"{key} {note}" for key, text in dates.items() if text and (note := parse_date(text)[1])]


#: ``ended=whole``: the decays whose file holds all of the decay (``records.DecayEnd.whole``, or not
#: said: a lab's own file); ``ended=any``: every one.
WHOLE, ANY = "whole", "any"


def ended_conditions(ended: str | None) -> list[sa.ColumnElement[bool]]:
    """A row is listed once, where its path holds its bytes (never a retired one); ``ended``: how its
    decay ended (a ``DecayEnd`` value, ``whole`` or ``any``; None: any)."""
    found: list[sa.ColumnElement[bool]] = [decays.c.retired_utc.is_(None)]
    if ended is None or ended == ANY:
        return found
    if ended == WHOLE:
        whole = [end.value for end in DecayEnd if end.whole]
        return [
            *found,
            decays.c.complete.is_(True),
            sa.or_(decays.c.ended.is_(None), decays.c.ended.in_(whole)),
        ]
    if ended not in {end.value for end in DecayEnd}:
        known = ", ".join([*(end.value for end in DecayEnd), WHOLE, ANY])
        raise BadCatalogueQuery(f"ended={ended!r}: give one of {known}")
    return [*found, decays.c.ended == ended]


def whole_unless_asked(query: RunQuery) -> RunQuery:
    """``query`` over the decays that ended whole, unless it names ``ended`` itself (``ended=any``):
    a stopped, cut or recovered decay's fit never stands for its condition by default."""
    if "ended" in query.equal:
        return query
    return RunQuery({**query.equal, "ended": WHOLE}, query.since, query.until, query.where)


def asks_ended(text: str | None) -> bool:
    """True when a ``--runs`` query names how its decays ended (``ended=any``, ``ended=stopped``): the
    decays it selects are then fitted as asked, partial ones included."""
    return text is not None and "ended" in parse_runs(text).equal


def _date(text: str) -> str:
    """A date as the catalogue compares it: UTC, ISO with a ``T`` (``literals.parse_date``)."""
    return parse_date(text)[0]


def _value(name: str, text: str) -> Any:
    """A value as its column holds it: numbers for numeric columns, drafts written as tankdaq writes."""
    column, text = FIELDS[name], checked_text(name, text)
    if name == "draft":
        try:
            return format_draft(parse_draft(text))
        except InputError as exc:
            raise BadCatalogueQuery(str(exc)) from None
    if name == "complete":
        if text.lower() not in ("true", "false", "yes", "no", "1", "0"):
            raise BadCatalogueQuery(f"complete={text!r}: give true or false")
        return text.lower() in ("true", "yes", "1")
    if isinstance(column.type, sa.Float | sa.Integer):
        return parse_number(name, text, column.type)
    if name == "recorded":
        return _date(text)
    return text


def parse_where(text: str) -> list[sa.ColumnElement[bool]]:
    """``field op value [and field op value ...]`` as bound conditions; anything else is one line."""
    found = []
    for clause in split_clauses(text):
        slip = operator_slip(clause)
        if slip is not None:
            raise BadCatalogueQuery(f"--where {clause.strip()!r}: {slip}")
        match = _CLAUSE.match(clause)
        if not match:
            raise BadCatalogueQuery(f"--where {clause!r} not understood: {WHERE_HELP}")
        name, op, value = match.groups()
        if name not in FIELDS:
            raise BadCatalogueQuery(f"--where: no field {name!r}; fields: {', '.join(FIELDS)}")
        value = _unquoted(value)
        if name in ("since", "until"):
            raise BadCatalogueQuery("--where: use --since/--until for dates, or recorded >= 2026-03")
        try:
            contains_text = op == "~" and name == "recorded"  # a part of the stored text, not a date
            bound = checked_text(name, value) if contains_text else _value(name, value)
            found.append(OPERATORS[op](FIELDS[name], bound))
        except BadCatalogueQuery as exc:
            raise BadCatalogueQuery(f"--where {clause!r}: {exc}") from None
    return found


def _unquoted(value: str) -> str:
    return value[1:-1] if value[:1] in "\"'" else value


#: The fields a query that found nothing names the values of (the catalogue's words, not hashes or paths).
LISTED = ("hull", "draft", "axis", "plan", "device", "firmware", "model", "source", "version")
LISTED_AT_MOST = 12


def absent_values(catalogue: Catalogue, query: RunQuery) -> list[str]:
    """For a query that found nothing: each ``=`` filter on a value no row holds, with the values the
    catalogue holds (``no hull 'SWATH'; the catalogue holds: kvlcc2, swath``), one line each."""
    lines = []
    with catalogue.reading() as connection:
        for name, text in _equalities(query):
            column = FIELDS[name]
            if connection.execute(sa.select(column).where(column == _value(name, text)).limit(1)).first():
                continue
            held = (
                connection.execute(
                    sa.select(column)
                    .where(column.is_not(None))
                    .distinct()
                    .order_by(column)
                    .limit(LISTED_AT_MOST + 1)
                )
                .scalars()
                .all()
            )
            shown = ", ".join(map(str, held[:LISTED_AT_MOST])) + (
                ", ..." if len(held) > LISTED_AT_MOST else ""
            )
            lines.append(
                f"no {name} {text!r}; "
                + (f"the catalogue holds: {shown}" if held else f"no run has a {name}")
            )
    return lines


def _equalities(query: RunQuery) -> list[tuple[str, str]]:
    """The ``name = value`` filters of ``query`` on ``LISTED`` fields (options, ``--runs``, ``--where``)."""
    found = [(name, value) for name, value in query.equal.items() if name in LISTED]
    for clause in split_clauses(query.where) if query.where else []:
        match = _CLAUSE.match(clause)
        if match and match.group(2) == "=" and match.group(1) in LISTED:
            found.append((match.group(1), _unquoted(match.group(3))))
    return found


def parse_runs(text: str) -> RunQuery:
    """``hull=swath draft=1.1T since=2026-03`` (``--runs``): ``key=value`` words, each key once
    (a rejected decay only with ``verdict=rejected`` or ``verdict=any``)."""
    equal: dict[str, str] = {}
    dates: dict[str, str] = {}
    for word in text.split():
        key, sep, value = word.partition("=")
        if not sep or not value:
            raise BadCatalogueQuery(
                f"--runs {word!r}: write key=value, e.g. hull=swath draft=1.1T since=2026-03"
            )
        if value[0] in "=<>!~":
            raise BadCatalogueQuery(
                f"--runs {word!r}: write {key}={value.lstrip('=<>!~')} (one =, no other operator)"
            )
        if key in ("since", "until"):
            dates[key] = value
        elif key in FIELDS:
            equal[key] = value
        else:
            raise BadCatalogueQuery(f"--runs: no field {key!r}; fields: since, until, {', '.join(FIELDS)}")
    if not equal and not dates:
        raise BadCatalogueQuery("--runs: give at least one key=value, e.g. hull=swath")
    return RunQuery(equal, dates.get("since"), dates.get("until"))


def select_rows(catalogue: Catalogue, query: RunQuery, with_exports: bool = False) -> list[dict[str, Any]]:
    """The rows that match, oldest first, as plain dicts (JSON columns decoded); ``with_exports``: each
    with ``exports``, the files ``tankdaq export`` wrote of it (``attach_exports``)."""
    statement = sa.select(decays).where(*query.conditions()).order_by(decays.c.recorded_utc, decays.c.id)
    with catalogue.reading() as connection:
        rows = [decoded(dict(row._mapping)) for row in connection.execute(statement)]
    return attach_exports(catalogue, rows) if with_exports else rows


#: What a run's ``exports`` say of each exported file.
EXPORT_FIELDS = ("format", "path", "decay", "size_bytes", "sha256")


def attach_exports(catalogue: Catalogue, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each row given ``exports``: its recording's exported files (``EXPORT_FIELDS`` each, by format,
    decay and path), tied to it by hash, or by the path they were exported from where they were
    indexed before their recording was catalogued."""
    by_hash = {row["sha256"]: row for row in rows}
    by_path = {row["path"]: row for row in rows}
    for row in rows:
        row["exports"] = []
    with catalogue.reading() as connection:
        for batch in in_batches(rows):
            untied = sa.and_(
                exports.c.source_sha256.is_(None), exports.c.source_path.in_([r["path"] for r in batch])
            )
            tied = exports.c.source_sha256.in_([r["sha256"] for r in batch])
            for found in connection.execute(sa.select(exports).where(sa.or_(tied, untied))):
                owner = (
                    by_hash.get(found.source_sha256)
                    if found.source_sha256
                    else by_path.get(found.source_path)
                )
                if owner is not None:
                    owner["exports"].append({name: getattr(found, name) for name in EXPORT_FIELDS})
    for row in rows:
        row["exports"].sort(key=lambda e: (e["format"], e["decay"] or 0, e["path"]))
    return rows


#: What ``runs --exports`` says of each exported file's run, after the file itself.
RUN_FIELDS = ("recorded_utc", "hull", "draft", "axis", "angle_nominal_deg", "verdict")


def export_listing(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per exported file of ``rows`` (``attach_exports``): the file (``export`` its path),
    then its run's condition and ``recording`` (the recording's path and hash): where a lab's HDF5,
    CSV, Parquet and .mat copies of these runs are."""
    listing = []
    for row in rows:
        for found in row["exports"]:
            entry = {"export" if name == "path" else name: value for name, value in found.items()}
            entry |= {name: row.get(name) for name in RUN_FIELDS}
            listing.append(entry | {"recording": row["path"], "recording_sha256": row["sha256"]})
    return listing


def decoded(row: dict[str, Any]) -> dict[str, Any]:
    """A row as read from the database, its JSON columns parsed (SQLite stores them as text)."""
    for key in ("checks", "coefficients", "b_eq_per_s", "b44_hat", "warnings"):
        if isinstance(row.get(key), str):
            row[key] = json.loads(row[key])
    return row


def flat(row: dict[str, Any]) -> dict[str, Any]:
    """One row as a table shows it: coefficients as columns, B_eq and B̂44 per standard amplitude."""
    hidden = ("coefficients", "b_eq_per_s", "b44_hat", "retired_utc")
    out = {k: v for k, v in row.items() if k not in hidden}
    for term, entry in (row.get("coefficients") or {}).items():
        out[term] = entry.get("value")
        out[f"{term}_ci_low"] = entry.get("ci_low")
        out[f"{term}_ci_high"] = entry.get("ci_high")
    for amplitude in STANDARD_AMPLITUDES_DEG:
        key = f"{amplitude:g}"
        out[f"b_eq_{key}deg_per_s"] = (row.get("b_eq_per_s") or {}).get(key)
        out[f"b44_hat_{key}deg"] = (row.get("b44_hat") or {}).get(key)
    out["checks"] = " | ".join(row.get("checks") or [])
    out["warnings"] = " | ".join(row.get("warnings") or [])
    if "exports" in row:  # each exported file's path (its format is its suffix)
        out["exports"] = " | ".join(found["path"] for found in row["exports"])
    return out


def paths_for(text: str, catalogue_url: str | None = None) -> list[Path]:
    """The files a ``--runs`` query names (complete recordings that exist), for identify, campaign
    and diagnose; none found is one line saying so."""
    return [Path(row["path"]) for row in rows_for(text, catalogue_url)]


def rows_for(text: str, catalogue_url: str | None = None) -> list[dict[str, Any]]:
    """The rows of ``paths_for``'s files (their ``id`` for a report's provenance), oldest first."""
    url = resolve_url(catalogue_url)
    if url is None:
        raise BadCatalogueQuery("--runs needs a catalogue: drop --catalogue none")
    query = parse_runs(text)
    with read_catalogue(url) as catalogue:
        complete = {**query.equal, "complete": "true"}
        rows = select_rows(catalogue, whole_unless_asked(RunQuery(complete, query.since, query.until)))
        partial = (
            []
            if "ended" in query.equal
            else select_rows(catalogue, RunQuery(complete, query.since, query.until))
        )
        absent = absent_values(catalogue, query) if not rows else []
    found = [row for row in rows if Path(row["path"]).is_file()]
    left_out = len(partial) - len(rows)
    said = f" ({left_out} that did not end whole left out: add ended=any)" if left_out > 0 else ""
    if not found:
        why = "".join(f"; {line}" for line in absent)
        raise BadCatalogueQuery(f"--runs {text!r}: no complete recording in the catalogue matches{said}{why}")
    return found


def runs(
    hull: str | None = None,
    draft: str | None = None,
    axis: str | None = None,
    since: str | None = None,
    verdict: str | None = None,
    where: str | None = None,
    catalogue: str | None = None,
    exports: bool = False,
    fits: str = "reference",
) -> pd.DataFrame:
    """The catalogued runs that match, as a pandas DataFrame (one row per decay; coefficients, B_eq
    and B̂44 at 2, 5 and 10 deg as columns; ``exports`` the paths of the files ``tankdaq export`` wrote
    of each, joined by `` | ``). ``exports=True``: one row per exported file instead (``export`` its
    path, ``format``, ``decay``, then its run's condition and ``recording``), as ``runs --exports``.
    ``fits="all"``: one row per fit kept of the decays that match (``id``, ``reference``, ``method``,
    ``model``, who and when), as ``runs --fits all``; the default reads each decay's reference fit.
    ``catalogue``: a URL or path (default: as the CLI), read only. ``since``: a date or time in UTC
    (``literals.parse_date``). Nothing found because a value is not there: a ``UserWarning`` names
    those that are; the empty frame keeps the columns (``empty_columns``)."""
    import pandas as pd

    from ..api.arguments import run_filters, text

    fits = text(fits, "fits", choices=("reference", "all"))
    given = {"hull": hull, "draft": draft, "axis": axis, "verdict": verdict, "since": since, "where": where}
    filters, catalogue, exports = run_filters(given, catalogue, exports)  # by name, before any connection
    hull, draft, axis, verdict, since, where = filters.values()
    equal = {k: v for k, v in {"hull": hull, "draft": draft, "axis": axis, "verdict": verdict}.items() if v}
    url = resolve_url(catalogue)
    if url is None:
        raise BadCatalogueQuery("the catalogue is switched off (none): give a catalogue")
    query = RunQuery(equal, since, None, where)
    with read_catalogue(url) as opened:
        rows = select_rows(opened, query, with_exports=True)
        if fits == "all":
            return pd.DataFrame(every_fit(opened, rows))
        absent = absent_values(opened, query) if not rows else []
    for line in absent:  # a notebook shows it: the frame is empty because the value is not there
        warnings.warn(line, UserWarning, stacklevel=2)
    listing = export_listing(rows) if exports else [flat(row) for row in rows]
    return pd.DataFrame(listing, columns=None if listing else empty_columns(exports))


def empty_columns(exports: bool = False) -> list[str]:
    """The columns of a result with no row (``tankdaq.runs()``, ``runs --csv``): those a row would have
    (``flat``, ``export_listing``), but the coefficients, which come with the fits found."""
    row: dict[str, Any] = {column.name: None for column in decays.c} | {"exports": []}
    if exports:
        row["exports"] = [dict.fromkeys(EXPORT_FIELDS)]
        return list(export_listing([row])[0])
    return list(flat(row))


def every_fit(catalogue: Catalogue, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every fit kept of the decays ``rows`` (``fits.fits_of``), flat as ``runs`` shows a row."""
    from .fits import fits_of

    return [{k: v for k, v in flat(fit).items() if k != "checks"} for fit in fits_of(catalogue, rows)]


def inputs_or_query(paths: list[Path] | None, query: str | None, catalogue: str | None) -> list[Path]:
    """The files a command reads: the paths given, or those ``--runs`` finds (one of the two)."""
    if paths and query:
        raise BadCatalogueQuery("give files or --runs QUERY, not both")
    if query:
        return paths_for(query, catalogue)
    if not paths:
        raise BadCatalogueQuery(
            'give the files to read, or --runs "hull=NAME draft=T ..." (docs/catalogue.md)'
        )
    return paths
