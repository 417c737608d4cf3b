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

from ..config.hulls import Hull
from ..errors import RecordingError
from ..records import Verdict
from ..store.inputs import file_sha256
from .database import Catalogue, CatalogueError, in_batches
from .fits import FitMethod, FitSource, add_fits, choose_reference, provenance
from .rows import (
    DECAY_SUFFIXES,
    FitHow,
    bare_row,
    decay_row,
    export_metadata,
    export_row,
    find_hull,
    fit_fields,
    utc_now,
)
from .schema import decays, exports, hulls, sessions

#: What a file seen again (moved, re-indexed, recovered) changes in its row: where it is, not what was
#: said about it (verdicts, later fits, the hull version it was recorded with).
LOCATION_COLUMNS = ("path", "size_bytes", "complete", "ended", "updated_utc")


def _insert(connection: sa.Connection, table: sa.Table) -> Any:
    """The dialect's INSERT that can say ON CONFLICT (SQLite and PostgreSQL spell it alike)."""
    if connection.dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert as pg_insert

        return pg_insert(table)
    from sqlalchemy.dialects.sqlite import insert as sqlite_insert

    return sqlite_insert(table)


def upsert_rows(connection: sa.Connection, rows: Sequence[Mapping[str, Any]], update: Iterable[str]) -> None:
    """Insert decay rows; a hash already there gets only the ``update`` columns. A new hash at a path
    whose row holds other bytes takes that row (``_take_paths``); the fit a row carries (``fit``: the
    one stored in its file) is kept (``fits.add_fits``). Rows with the same columns go as one statement
    with many parameter sets (compiled once, cached)."""
    wanted = tuple(update) + (("retired_utc",) if "path" in update else ())
    carried = {row["sha256"]: row["fit"] for row in rows if row.get("fit")}
    plain = [{k: v for k, v in row.items() if k != "fit"} | {"retired_utc": None} for row in rows]
    plain, replaced = _take_paths(connection, plain)
    shapes: dict[tuple[str, ...], list[Mapping[str, Any]]] = {}
    for row in plain:
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
    _retire_others(connection, [*plain, *replaced])
    _keep_fits(connection, carried, [row["sha256"] for row in replaced])


def _take_paths(
    connection: sa.Connection, rows: list[dict[str, Any]]
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Rows of new bytes at a path whose (live) row holds other bytes: that row is given these bytes
    (a file replaced under its name; a recording catalogued while it was written, now closed), so a
    path has one row. A row that describes bytes the path no longer holds (read before the file grew,
    or cut where a complete row is there) is dropped. Returns (rows to upsert, rows that replaced)."""
    known = _found(connection, decays.c.sha256, [row["sha256"] for row in rows])
    new = [row for row in rows if row["sha256"] not in known]
    live = _found(connection, decays.c.path, [row["path"] for row in new], live=True)
    keep, replaced = [], []
    for row in rows:
        old = live.get(row["path"]) if row["sha256"] not in known else None
        if old is None:
            keep.append(row)
        elif not _stale(row, old):
            fresh = {k: v for k, v in row.items() if k not in ("created_utc", "retired_utc")}
            connection.execute(decays.update().where(decays.c.id == old.id).values(**fresh, retired_utc=None))
            replaced.append(row)
    return keep, replaced


def _found(connection: sa.Connection, column: Any, values: list[Any], live: bool = False) -> dict[Any, Any]:
    """The rows whose ``column`` is one of ``values``, by that value (``live``: rows not retired)."""
    found: dict[Any, Any] = {}
    for batch in in_batches(values):
        statement = sa.select(decays.c.id, decays.c.sha256, decays.c.path, decays.c.complete)
        statement = statement.where(column.in_(batch))
        if live:
            statement = statement.where(decays.c.retired_utc.is_(None))
        found |= {getattr(row, column.name): row for row in connection.execute(statement)}
    return found


def _stale(row: Mapping[str, Any], old: Any) -> bool:
    """A row made of bytes its path no longer holds: a provisional row arriving after the complete one,
    or a file whose size has changed since it was read."""
    if old.complete and not row.get("complete"):
        return True
    path = Path(row["path"])
    return path.is_file() and path.stat().st_size != row.get("size_bytes")


def _retire_others(connection: sa.Connection, rows: Sequence[Mapping[str, Any]]) -> None:
    """A path has one live row: any other row there (of bytes the path no longer holds) is retired —
    kept with its fits, never listed."""
    if rows:
        statement = (
            decays.update()
            .where(
                decays.c.path == sa.bindparam("at"),
                decays.c.sha256 != sa.bindparam("bytes"),
                decays.c.retired_utc.is_(None),
            )
            .values(retired_utc=utc_now())
        )
        connection.execute(statement, [{"at": row["path"], "bytes": row["sha256"]} for row in rows])


def _keep_fits(
    connection: sa.Connection, carried: Mapping[str, Mapping[str, Any]], replaced: list[str]
) -> None:
    """The fits rows carried kept on their rows; a replaced row's reference chosen anew (its old
    bytes' fits are not its bytes')."""
    rows = _found(connection, decays.c.sha256, [*carried, *replaced])
    add_fits(connection, [(_decay(rows[sha]), fit) for sha, fit in carried.items() if sha in rows])
    for sha in replaced:
        if sha in rows and sha not in carried:
            choose_reference(connection, rows[sha].id)


def _decay(row: Any) -> dict[str, Any]:
    return {"id": row.id, "sha256": row.sha256, "path": row.path}


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
            statement = sa.select(decays.c.path).where(
                decays.c.path.in_(batch), decays.c.retired_utc.is_(None)
            )
            for (found,) in connection.execute(statement):
                resolved.pop(found, None)
    return list(resolved.values())


def add_file(
    catalogue: Catalogue,
    path: Path,
    extra: Mapping[str, Any] | None = None,
    unreadable: bool = False,
    sha256: str | None = None,
    fit: Mapping[str, Any] | None = None,
) -> str:
    """Catalogue one decay file, a recording or a lab's CSV (after the file is closed); returns its
    hash. ``extra`` columns (a verdict, a session) are written too, on a new row or an existing one; a
    decay a session accepted keeps the fit its file holds as the session's (``FitSource.SESSION``). A
    file that cannot be read raises ``RecordingError``, or with ``unreadable`` gets a bare row (a
    session's decay cut early). ``sha256``: the file's, when the caller has just hashed it; ``fit``: a
    fit of these bytes to keep too."""
    try:
        row, version = decay_row(path, sha256, (extra or {}).get("axis"))
    except RecordingError:
        if not unreadable:
            raise
        row, version = bare_row(path), None
    row |= dict(extra or {})
    row["updated_utc"] = max(row["updated_utc"], row["created_utc"])  # a fit made before its row was
    add_rows(catalogue, [(row, version)], [*LOCATION_COLUMNS, *(extra or {})])
    kept = [dict(fit)] if fit is not None else []
    if row.get("fit") and (extra or {}).get("verdict") == Verdict.ACCEPTED:
        kept.append(dict(row["fit"]) | {"source": FitSource.SESSION.value} | provenance())
    if kept:
        with catalogue.engine.begin() as connection:
            found = _found(connection, decays.c.sha256, [row["sha256"]]).get(row["sha256"])
            if found is not None:  # else dropped: the path holds newer bytes than these
                add_fits(connection, [(_decay(found), one) for one in kept])
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


#: The files a fit read: each path with the SHA-256 of the bytes read (None: not known).
Files = Sequence[tuple[Path, str | None]]


def update_fit(catalogue: Catalogue, files: Files, fit: Mapping[str, Any]) -> int:
    """Keep a fit (identify, campaign, diagnose) on the rows of the bytes it read, in one transaction
    (the reference fit changes only by ``fits.rank``); a decay file (a recording, a lab's CSV) not
    catalogued yet is added first. A CSV ``tankdaq export`` wrote is its recording's copy, not a decay
    of its own: its fit is not kept. Returns the rows written."""
    return update_fits(catalogue, [(files, fit)])


def update_fits(catalogue: Catalogue, fitted: Sequence[tuple[Files, Mapping[str, Any]]]) -> int:
    """``update_fit`` of many fits (a campaign's batch of groups) in one transaction. A file whose
    bytes are no longer the ones read (replaced since) gets no fit: one line names it."""
    missing: list[tuple[Path, str, Mapping[str, Any]]] = []
    unknown: list[Path] = []
    written = 0
    with catalogue.engine.begin() as connection:
        for files, fit in fitted:
            kept = [(p.resolve(), sha) for p, sha in files if p.suffix.lower() in DECAY_SUFFIXES]
            read = [(path, sha) for path, sha in kept if not _exported(path)]
            unknown += [path for path, sha in read if sha is None]
            shas = [sha for _, sha in read if sha is not None]
            rows = _found(connection, decays.c.sha256, shas)
            add_fits(connection, [(_decay(rows[sha]), _fit(fit)) for sha in shas if sha in rows])
            axis = fit.get("axis")
            if axis and (ids := [rows[sha].id for sha in shas if sha in rows]):
                connection.execute(decays.update().where(decays.c.id.in_(ids)).values(axis=axis))
            missing += [(path, sha, fit) for path, sha in read if sha is not None and sha not in rows]
            written += len(shas)
    for path, sha, fit in missing:
        if path.is_file() and file_sha256(path) == sha:
            add_file(
                catalogue, path, {"axis": fit["axis"]} if fit.get("axis") else None, sha256=sha, fit=_fit(fit)
            )
        else:
            unknown.append(path)
    if unknown:
        names = ", ".join(str(path) for path in unknown[:3]) + (" ..." if len(unknown) > 3 else "")
        raise CatalogueError(
            f"{names}: the bytes fitted are no longer in the file; that fit is not catalogued"
        )
    return written


def _fit(fit: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in fit.items() if k != "axis"}


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
    from ..session.journal import SessionLog

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
            "checks": _reasons(run, verdict),
        }
        add_file(catalogue, path, extra, unreadable=True)  # cut before any data: still the session's
        done += 1
    hull_name = str(plan["hull"]) if plan.get("hull") else None
    _upsert_session(catalogue, folder, sid, plan_name, hull_name, records, runs, verdicts)
    return done


def _reasons(run: Mapping[str, Any], verdict: Mapping[str, Any]) -> list[str]:
    """Why a decay was judged as it was: the checks' reasons; a rejection no check asked for says who
    rejected it (the operator's answer, or the session stopping during the decay)."""
    reasons = [str(r) for r in verdict.get("reasons", run.get("reasons", []))]
    if reasons or verdict.get("verdict") != Verdict.REJECTED:
        return reasons
    action = verdict.get("action")
    if action == "stopped":
        return ["the session stopped during this decay"]
    return [f"the operator chose: {action}" if action else "rejected by the operator"]


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
        "accepted": sum(1 for v in verdicts.values() if v.get("verdict") == Verdict.ACCEPTED),
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
    source: FitSource,
    fit: Any,
    runs: Sequence[Any],
    warnings: Sequence[str] = (),
    model: str | None = None,
    hull: Hull | None = None,
    how: FitHow | None = None,
) -> dict[str, Any]:
    """A fitted estimator's fit (``coefficients_``, ``ci95_``, ``r2_angle_`` when it has one) for
    the condition its runs carry in their metadata (``hull``: theirs, when the caller has it); ``how``:
    its method (default: the estimator's own class, output error or equation error)."""
    condition = _condition(runs, hull)
    ci95 = {term: tuple(pair) for term, pair in getattr(fit, "ci95_", {}).items()}
    r2 = getattr(fit, "r2_angle_", None)
    how = how or FitHow(_method_of(fit))
    return fit_fields(source, fit.coefficients_, ci95, r2, warnings, condition, model, how)


def _method_of(estimator: Any) -> FitMethod:
    from ..ident.equation_error import EquationErrorFit
    from ..ident.output_error import OutputErrorFit

    if isinstance(estimator, OutputErrorFit):
        return FitMethod.OUTPUT_ERROR
    return FitMethod.EQUATION_ERROR if isinstance(estimator, EquationErrorFit) else FitMethod.OTHER


def run_files(runs: Sequence[Any]) -> list[tuple[Path, str | None]]:
    """The files runs were read from (``meta["file"]``), once each, with the SHA-256 of the bytes read
    (``meta["sha256"]``, set by ``store.inputs.read_runs``)."""
    found = {str(r.meta["file"]): r.meta.get("sha256") for r in runs if r.meta.get("file")}
    return [(Path(path), sha) for path, sha in found.items()]


def campaign_fit(result: Any) -> tuple[list[tuple[Path, str | None]], dict[str, Any]] | None:
    """A campaign group's fit (``campaign.groups.GroupResult``) as (its files, its fit); None for a
    group that was not fitted. Uses the group's own hull and warnings: nothing is read or found again."""
    if result.fit is None:
        return None
    settings = {
        "joint": "the group's repeats together",
        "runs": len(result.runs),
        "model_choice": result.model_reason,
    }
    how = FitHow(_method_of(result.fit), model_by_data=result.model_by_data, settings=settings)
    fit = fit_of_estimator(
        FitSource.CAMPAIGN, result.fit, result.runs, result.warnings, hull=result.hull, how=how
    )
    return run_files(result.runs), fit | {"budget": list(result.budget)}


def record_fits(catalogue: Catalogue, results: Iterable[Any]) -> int:
    """A campaign's group fits (``campaign.groups.GroupResult``) onto each group's recordings, in one
    transaction. Returns the rows updated."""
    return update_fits(catalogue, [fit for result in results if (fit := campaign_fit(result)) is not None])


def fit_of_summary(source: FitSource, summary: Mapping[str, Any], runs: Sequence[Any]) -> dict[str, Any]:
    """An identify or diagnose summary's fit (``ident.report.summarize``) as the catalogue keeps it:
    its method, and whether the data chose its model (``summary["model_choice"]`` holds the scores)."""
    condition = _condition(runs)
    table = summary["coefficients"]
    coefficients = {term: entry["value"] for term, entry in table.items()}
    ci95 = {term: tuple(entry["ci95"]) for term, entry in table.items() if entry.get("ci95")}
    model = summary.get("model", {}).get("name")
    warnings = summary.get("warnings", [])
    choice = summary.get("model_choice") or {}
    option = str(summary.get("method", ""))
    settings = {"method": option, "intervals": summary.get("intervals"), "model_choice": choice.get("reason")}
    how = FitHow(FitMethod.of_option(option), model_by_data="scores" in choice, settings=settings)
    fit = fit_fields(source, coefficients, ci95, summary.get("r2_angle"), warnings, condition, model, how)
    return fit | {"budget": list(summary.get("budget", []))}
