"""Adding and updating rows: a file (found again by its SHA-256 wherever it moved), a session's
verdicts, a fit made by identify, campaign or diagnose. Every write is one transaction; a row is keyed
by the file's hash, so writing the same file twice, or from two processes, makes one row.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from ..config import Hull
from ..errors import RecordingError
from .database import Catalogue, decays, exports, hulls, in_batches, sessions
from .rows import (
    DECAY_SUFFIXES,
    bare_row,
    decay_row,
    export_metadata,
    export_row,
    find_hull,
    fit_fields,
    utc_now,
)

#: What a file seen again (moved, re-indexed, recovered) changes in its row: where it is, not what was
#: said about it (verdicts, later fits, the hull version it was recorded with).
LOCATION_COLUMNS = ("path", "size_bytes", "complete", "updated_utc")


def _insert(connection: sa.Connection, table: sa.Table) -> Any:
    """The dialect's INSERT that can say ON CONFLICT (SQLite and PostgreSQL spell it alike)."""
    if connection.dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert as pg_insert

        return pg_insert(table)
    from sqlalchemy.dialects.sqlite import insert as sqlite_insert

    return sqlite_insert(table)


def upsert_rows(connection: sa.Connection, rows: Sequence[Mapping[str, Any]], update: Iterable[str]) -> None:
    """Insert decay rows; a hash already there gets only the ``update`` columns. Rows with the same
    columns go as one statement with many parameter sets (compiled once, cached)."""
    wanted = tuple(update)
    shapes: dict[tuple[str, ...], list[Mapping[str, Any]]] = {}
    for row in rows:
        shapes.setdefault(tuple(sorted(row)), []).append(row)
    for columns, group in shapes.items():
        statement = _insert(connection, decays)
        changed = {c: statement.excluded[c] for c in wanted if c in columns}
        upsert = (
            statement.on_conflict_do_update(index_elements=["sha256"], set_=changed)
            if changed
            else statement.on_conflict_do_nothing(index_elements=["sha256"])
        )
        connection.execute(upsert, [dict(row) for row in group])


def _add_hull(connection: sa.Connection, version: Mapping[str, Any] | None) -> None:
    if version is not None:
        statement = _insert(connection, hulls).values(**version)
        connection.execute(statement.on_conflict_do_nothing(index_elements=["sha256"]))


Made = tuple[Mapping[str, Any], Mapping[str, Any] | None]  # a decay row and its hull's version


def add_rows(catalogue: Catalogue, made: Sequence[Made], update: Iterable[str] = LOCATION_COLUMNS) -> None:
    """Decay rows made from their files (``rows.decay_row``) and their hulls' versions, in one
    transaction; a hash already there gets only the ``update`` columns (where the file is now)."""
    versions = {version["sha256"]: version for _, version in made if version is not None}
    with catalogue.engine.begin() as connection:
        for version in versions.values():
            _add_hull(connection, version)
        upsert_rows(connection, [row for row, _ in made], update)


def missing_paths(catalogue: Catalogue, paths: Sequence[Path]) -> list[Path]:
    """The decay files among ``paths`` that have no row at their path (a moved one is found again by
    its hash when its row is written)."""
    resolved = {str(path.resolve()): path for path in paths if path.suffix.lower() in DECAY_SUFFIXES}
    names = list(resolved)
    with catalogue.reading() as connection:
        for batch in in_batches(names):
            for (found,) in connection.execute(sa.select(decays.c.path).where(decays.c.path.in_(batch))):
                resolved.pop(found, None)
    return list(resolved.values())


def add_file(
    catalogue: Catalogue,
    path: Path,
    extra: Mapping[str, Any] | None = None,
    unreadable: bool = False,
    sha256: str | None = None,
) -> str:
    """Catalogue one decay file, a recording or a lab's CSV (after the file is closed); returns its
    hash. ``extra`` columns (a verdict, a session) are written too, on a new row or an existing one. A
    file that cannot be read raises ``RecordingError``, or with ``unreadable`` gets a bare row (a
    session's decay cut early). ``sha256``: the file's, when the caller has just hashed it."""
    try:
        row, version = decay_row(path, sha256, (extra or {}).get("axis"))
    except RecordingError:
        if not unreadable:
            raise
        row, version = bare_row(path), None
    row |= dict(extra or {})
    row["updated_utc"] = max(row["updated_utc"], row["created_utc"])  # a fit made before its row was
    add_rows(catalogue, [(row, version)], [*LOCATION_COLUMNS, *(extra or {})])
    return str(row["sha256"])


def add_export(catalogue: Catalogue, path: Path, metadata: dict[str, Any], sha256: str | None = None) -> str:
    """Catalogue a file ``tankdaq export`` wrote (``rows.export_metadata``) in ``exports``, tied to the
    row of the recording it came from when that is catalogued; returns its hash."""
    row = export_row(path, metadata, sha256)
    with catalogue.engine.begin() as connection:
        if row["source_path"] is not None:
            found = connection.execute(sa.select(decays.c.sha256).where(decays.c.path == row["source_path"]))
            row["source_sha256"] = found.scalar()
        statement = _insert(connection, exports).values(**row)
        keep = {c: statement.excluded[c] for c in ("path", "size_bytes", "source_sha256", "updated_utc")}
        connection.execute(statement.on_conflict_do_update(index_elements=["sha256"], set_=keep))
    return str(row["sha256"])


def update_fit(catalogue: Catalogue, paths: Sequence[Path], fields: Mapping[str, Any]) -> int:
    """Give the rows of ``paths`` a fit (identify, campaign, diagnose) in one transaction; a decay file
    (a recording, a lab's CSV) not catalogued yet is added first. A CSV ``tankdaq export`` wrote is its
    recording's copy, not a decay of its own: its fit is not written. Returns the rows written."""
    return update_fits(catalogue, [(paths, fields)])


def update_fits(catalogue: Catalogue, fits: Sequence[tuple[Sequence[Path], Mapping[str, Any]]]) -> int:
    """``update_fit`` of many fits (a campaign's batch of groups) in one transaction."""
    missing: list[tuple[Path, Mapping[str, Any]]] = []
    written = 0
    with catalogue.engine.begin() as connection:
        for paths, fields in fits:
            files = [p.resolve() for p in paths if p.suffix.lower() in DECAY_SUFFIXES and p.is_file()]
            for path in files:
                if _exported(path):
                    continue
                written += 1
                statement = decays.update().where(decays.c.path == str(path)).values(**fields)
                if not connection.execute(statement).rowcount:
                    missing.append((path, fields))
    for path, fields in missing:
        add_file(catalogue, path, fields)
    return written


def _exported(path: Path) -> bool:
    """A file ``tankdaq export`` wrote: its recording's copy, not a decay of its own (so no fit of its
    own); a file the export readers cannot read counts as the lab's own decay file."""
    try:
        return export_metadata(path) is not None
    except RecordingError:
        return False


def session_id(log_path: Path) -> str:
    """A session's id: the hash of its log's first line (the plan, with when it began), so the id
    follows the folder when it moves."""
    with log_path.open("rb") as fh:
        return hashlib.sha256(fh.readline()).hexdigest()[:32]


def record_session(catalogue: Catalogue, folder: Path, only: str | None = None) -> int:
    """The session in ``folder`` (its ``session.jsonl``): its row, and each decay's file with the
    session, plan, decay number, the operator's verdict and the checks' reasons. Returns the decays
    catalogued (a decay whose file is gone is left out: the log says it was rejected as missing).
    ``only``: the one file just judged (a session's verdict; the others are already there)."""
    from ..acquire.guided.journal import SessionLog

    log = SessionLog(folder)
    records = log.read()
    if not records:
        return 0
    sid = session_id(log.path)
    plan = next((r for r in records if r.get("type") == "plan"), {})
    plan_name = str((plan.get("plan") or {}).get("name", "")) or None
    runs = {r["decay"]: r for r in records if r.get("type") == "run"}
    verdicts = {r["decay"]: r for r in records if r.get("type") == "verdict"}
    done = 0
    for decay, run in sorted(runs.items()):
        path = folder / run["file"]
        if not path.is_file() or only not in (None, run["file"]):
            continue
        verdict = verdicts.get(decay, {})
        extra = {
            "session_id": sid,
            "plan": plan_name,
            "decay_number": decay,
            "verdict": verdict.get("verdict"),
            "checks": list(verdict.get("reasons", run.get("reasons", []))),
        }
        add_file(catalogue, path, extra, unreadable=True)  # cut before any data: still the session's
        done += 1
    hull_name = str(plan["hull"]) if plan.get("hull") else None
    _upsert_session(catalogue, folder, sid, plan_name, hull_name, records, runs, verdicts)
    return done


def _upsert_session(
    catalogue: Catalogue,
    folder: Path,
    sid: str,
    plan_name: str | None,
    hull_name: str | None,
    records: list[dict[str, Any]],
    runs: Mapping[int, Any],
    verdicts: Mapping[int, Mapping[str, Any]],
) -> None:
    row = {
        "session_id": sid,
        "folder": str(folder.resolve()),
        "plan": plan_name,
        "hull": hull_name,
        "started_utc": records[0].get("at"),
        "decays": len(runs),
        "accepted": sum(1 for v in verdicts.values() if v.get("verdict") == "accepted"),
        "updated_utc": utc_now(),
    }
    with catalogue.engine.begin() as connection:
        statement = _insert(connection, sessions).values(**row)
        keep = {c: statement.excluded[c] for c in row if c not in ("session_id", "started_utc")}
        connection.execute(statement.on_conflict_do_update(index_elements=["session_id"], set_=keep))


def _condition(runs: Sequence[Any], hull: Hull | None = None) -> tuple[Hull | None, str | None, str | None]:
    """Hull, draft and axis of fitted runs (their metadata, else their file names: ``condition_of``);
    ``hull``: the one already loaded for them (a campaign's group), else it is looked up by name."""
    from ..ident.conditions import condition_of

    if not runs:
        return None, None, None
    condition = condition_of(runs[0])
    found = hull if hull is not None and hull.name == condition.hull else find_hull(condition.hull)
    return found, condition.draft, condition.axis


def fit_of_estimator(
    source: str,
    fit: Any,
    runs: Sequence[Any],
    warnings: Sequence[str] = (),
    model: str | None = None,
    hull: Hull | None = None,
) -> dict[str, Any]:
    """A fitted estimator's columns (``coefficients_``, ``ci95_``, ``r2_angle_`` when it has one) for
    the condition its runs carry in their metadata (``hull``: theirs, when the caller has it)."""
    condition = _condition(runs, hull)
    ci95 = {term: tuple(pair) for term, pair in getattr(fit, "ci95_", {}).items()}
    r2 = getattr(fit, "r2_angle_", None)
    return fit_fields(source, fit.coefficients_, ci95, r2, warnings, condition, model)


def run_paths(runs: Sequence[Any]) -> list[Path]:
    """The files runs were read from (``meta["file"]``), once each."""
    return [Path(p) for p in dict.fromkeys(str(r.meta["file"]) for r in runs if r.meta.get("file"))]


def campaign_fit(result: Any) -> tuple[list[Path], dict[str, Any]] | None:
    """A campaign group's fit (``ident.campaign.GroupResult``) as (its files, its columns); None for a
    group that was not fitted. Uses the group's own hull and warnings: nothing is read or found again."""
    if result.fit is None:
        return None
    fields = fit_of_estimator("campaign", result.fit, result.runs, result.warnings, hull=result.hull)
    return run_paths(result.runs), fields


def record_fits(catalogue: Catalogue, results: Iterable[Any]) -> int:
    """A campaign's group fits (``ident.campaign.GroupResult``) onto each group's recordings, in one
    transaction. Returns the rows updated."""
    return update_fits(catalogue, [fit for result in results if (fit := campaign_fit(result)) is not None])


def fit_of_summary(source: str, summary: Mapping[str, Any], runs: Sequence[Any]) -> dict[str, Any]:
    """An identify or diagnose summary's fit (``ident.report.summarize``) as catalogue columns."""
    condition = _condition(runs)
    table = summary["coefficients"]
    coefficients = {term: entry["value"] for term, entry in table.items()}
    ci95 = {term: tuple(entry["ci95"]) for term, entry in table.items() if entry.get("ci95")}
    model = summary.get("model", {}).get("name")
    warnings = summary.get("warnings", [])
    return fit_fields(source, coefficients, ci95, summary.get("r2_angle"), warnings, condition, model)
