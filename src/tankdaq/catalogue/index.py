"""``tankdaq catalogue index DIR``: the catalogue rebuilt from the files, idempotently.

Every decay file (a recording, a lab's CSV decay) and every file ``tankdaq export`` wrote (HDF5, Parquet,
MATLAB, a CSV with its sidecar) is known by its SHA-256: a file seen before is left alone, a file that
moved has its path updated, a new one is read and added (an export to ``exports``, tied to its
recording); each session folder's log then gives its decays their verdicts. Running it twice changes
nothing; a catalogue lost or never written is made again from here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import sqlalchemy as sa

from ..errors import RecordingError
from ..store.inputs import file_sha256
from .database import Catalogue, in_batches
from .rows import DECAY_SUFFIXES, decay_row, export_metadata, utc_now
from .schema import decays, exports
from .writing import Made, add_export, add_rows, record_session

#: New decay rows go into the catalogue this many to a transaction (one transaction a file cost more than
#: making its row: ``bench/bench_catalogue_campaign.py``).
INDEX_BATCH = 200


@dataclass
class IndexReport:
    """What an index did, file by file."""

    added: list[Path] = field(default_factory=list)
    moved: list[Path] = field(default_factory=list)
    unchanged: list[Path] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # one line each: the file and why
    sessions: int = 0
    exports: int = 0  # of those added, files exported from a recording
    retired: list[Path] = field(default_factory=list)  # rows of bytes their path no longer holds
    incomplete: list[Path] = field(default_factory=list)  # added as not complete: cut short or corrupted

    @property
    def line(self) -> str:
        exported = f"; {self.exports} of those added are exports of a recording" if self.exports else ""
        if self.retired:
            exported += f"; {len(self.retired)} row(s) retired: their path holds other bytes now"
        return (
            f"{len(self.added)} added, {len(self.moved)} moved, {len(self.unchanged)} unchanged, "
            f"{len(self.skipped)} skipped, {self.sessions} session(s){exported}"
        )


def index_folder(
    catalogue: Catalogue, folder: Path, progress: Callable[[Path], None] | None = None
) -> IndexReport:
    """Catalogue every decay file and export under ``folder`` and every session log in it."""
    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in DECAY_SUFFIXES and p.is_file())
    report = index_files(catalogue, files, progress)
    for log in sorted(folder.rglob("session.jsonl")):
        report.sessions += bool(record_session(catalogue, log.parent))
    return report


def index_files(
    catalogue: Catalogue, files: list[Path], progress: Callable[[Path], None] | None = None
) -> IndexReport:
    """Catalogue the decay files and exports ``files`` (``index_folder`` without the sessions: what
    ``tankdaq import`` has just written)."""
    report = IndexReport()
    files = sorted(files, key=lambda p: p.suffix.lower() != ".mcap")  # recordings first: exports find rows
    hashes = _readable(files, report)
    known, retired = _known_paths(catalogue, list(hashes.values()))
    pending: list[Made] = []  # new decay rows, written INDEX_BATCH to a transaction
    for path, sha in hashes.items():
        where = known.get(sha)
        if sha in retired:  # bytes whose row was retired, seen again: the row comes back, here
            _move(catalogue, decays, sha, path)
            retired.discard(sha)
            report.moved.append(path)
        elif where is not None and (where[0] == str(path.resolve()) or Path(where[0]).is_file()):
            report.unchanged.append(path)  # seen here before, or a copy of a file still in its place
        elif where is not None:
            _move(catalogue, where[1], sha, path)
            report.moved.append(path)
        else:
            try:
                table = _add(catalogue, path, sha, pending)
            except (RecordingError, OSError) as exc:  # not a decay tankdaq reads, nor an export of one
                said = str(exc)  # a reader's line names the file itself
                report.skipped.append(said if said.startswith(str(path)) else f"{path}: {said}")
            else:
                report.added.append(path)
                report.exports += table is exports
                if table is decays and not pending[-1][0]["complete"]:
                    report.incomplete.append(path)
                known[sha] = (str(path.resolve()), table)
        if len(pending) >= INDEX_BATCH:
            _flush(catalogue, pending)
        if progress is not None:
            progress(path)
    _flush(catalogue, pending)
    report.retired = retire_stale(catalogue, hashes)
    return report


def _readable(files: list[Path], report: IndexReport) -> dict[Path, str]:
    """Each file's SHA-256; one that cannot be read (permissions, a bad sector) is listed as skipped,
    and the others are indexed."""
    hashes = {}
    for path in files:
        try:
            hashes[path] = file_sha256(path)
        except OSError as exc:
            report.skipped.append(f"{path}: not readable ({exc.strerror or exc})")
    return hashes


def _add(catalogue: Catalogue, path: Path, sha: str, pending: list[Made]) -> sa.Table:
    """A new file into its table: an export (``rows.export_metadata``), after the decay rows made
    before it (its recording's among them), or a decay's row into ``pending``; returns the table."""
    metadata = export_metadata(path)
    if metadata is not None:
        _flush(catalogue, pending)
        add_export(catalogue, path, metadata, sha)
        return exports
    pending.append(decay_row(path, sha))
    return decays


def _flush(catalogue: Catalogue, pending: list[Made]) -> None:
    if pending:
        add_rows(catalogue, pending)
        pending.clear()


def _known_paths(catalogue: Catalogue, hashes: list[str]) -> tuple[dict[str, tuple[str, sa.Table]], set[str]]:
    """Where each hash already catalogued is, and in which table; and the decays' retired ones."""
    found: dict[str, tuple[str, sa.Table]] = {}
    retired: set[str] = set()
    with catalogue.reading() as connection:
        for table in (decays, exports):
            gone = table.c.retired_utc.is_not(None) if table is decays else sa.false()
            for batch in in_batches(hashes):
                rows = connection.execute(
                    sa.select(table.c.sha256, table.c.path, gone).where(table.c.sha256.in_(batch))
                )
                for sha, path, is_retired in rows:
                    found[sha] = (path, table)
                    if is_retired:
                        retired.add(sha)
    return found, retired


def _move(catalogue: Catalogue, table: sa.Table, sha: str, path: Path) -> None:
    with catalogue.engine.begin() as connection:
        connection.execute(
            table.update()
            .where(table.c.sha256 == sha)
            .values(path=str(path.resolve()), size_bytes=path.stat().st_size, updated_utc=utc_now())
        )
        if table is decays:
            connection.execute(decays.update().where(decays.c.sha256 == sha).values(retired_utc=None))


def retire_stale(catalogue: Catalogue, hashes: dict[Path, str]) -> list[Path]:
    """Retire the rows at these paths that hold other bytes than the files there now (replaced by a
    copy of a file catalogued elsewhere): a path lists one row, the retired one keeps its fits."""
    by_path = {str(path.resolve()): sha for path, sha in hashes.items()}
    stale: list[tuple[int, str]] = []
    with catalogue.reading() as connection:
        for batch in in_batches(list(by_path)):
            statement = sa.select(decays.c.id, decays.c.path, decays.c.sha256)
            statement = statement.where(decays.c.path.in_(batch), decays.c.retired_utc.is_(None))
            stale += [
                (row.id, row.path) for row in connection.execute(statement) if row.sha256 != by_path[row.path]
            ]
    if stale:
        with catalogue.engine.begin() as connection:
            ids = [found for found, _ in stale]
            connection.execute(decays.update().where(decays.c.id.in_(ids)).values(retired_utc=utc_now()))
    return [Path(path) for _, path in stale]
