"""``tankdaq catalogue index DIR``: the catalogue rebuilt from the files, idempotently.

Every recording is known by its SHA-256: a file seen before is left alone, a file that moved has its
path updated, a new one is read and added; each session folder's log then gives its decays their
verdicts. Running it twice changes nothing; a catalogue lost or never written is made again from here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import sqlalchemy as sa

from ..errors import RecordingError
from .database import Catalogue, decays
from .rows import file_sha256, utc_now
from .writing import add_file, record_session

#: How many hashes one look-up asks for (a bound parameter list, well under every driver's limit).
LOOKUP_BATCH = 500


@dataclass
class IndexReport:
    """What an index did, file by file."""

    added: list[Path] = field(default_factory=list)
    moved: list[Path] = field(default_factory=list)
    unchanged: list[Path] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # one line each: the file and why
    sessions: int = 0

    @property
    def line(self) -> str:
        return (
            f"{len(self.added)} added, {len(self.moved)} moved, {len(self.unchanged)} unchanged, "
            f"{len(self.skipped)} skipped, {self.sessions} session(s)"
        )


def index_folder(
    catalogue: Catalogue, folder: Path, progress: Callable[[Path], None] | None = None
) -> IndexReport:
    """Catalogue every ``.mcap`` recording under ``folder`` and every session log in it."""
    report = IndexReport()
    files = sorted(p for p in folder.rglob("*.mcap") if p.is_file())
    hashes = {path: file_sha256(path) for path in files}
    known = _known_paths(catalogue, list(hashes.values()))
    for path, sha in hashes.items():
        where = known.get(sha)
        if where == str(path.resolve()) or (where is not None and Path(where).is_file()):
            report.unchanged.append(path)  # seen here before, or a copy of a file still in its place
        elif where is not None:
            _move(catalogue, sha, path)
            report.moved.append(path)
        else:
            try:
                add_file(catalogue, path)
            except RecordingError as exc:  # not a tankdaq recording, or cut to nothing readable
                report.skipped.append(f"{path}: {exc}")
            else:
                report.added.append(path)
                known[sha] = str(path.resolve())
        if progress is not None:
            progress(path)
    for log in sorted(folder.rglob("session.jsonl")):
        report.sessions += bool(record_session(catalogue, log.parent))
    return report


def _known_paths(catalogue: Catalogue, hashes: list[str]) -> dict[str, str]:
    found: dict[str, str] = {}
    with catalogue.reading() as connection:
        for start in range(0, len(hashes), LOOKUP_BATCH):
            batch = hashes[start : start + LOOKUP_BATCH]
            rows = connection.execute(
                sa.select(decays.c.sha256, decays.c.path).where(decays.c.sha256.in_(batch))
            )
            found.update({sha: path for sha, path in rows})
    return found


def _move(catalogue: Catalogue, sha: str, path: Path) -> None:
    with catalogue.engine.begin() as connection:
        connection.execute(
            decays.update()
            .where(decays.c.sha256 == sha)
            .values(path=str(path.resolve()), size_bytes=path.stat().st_size, updated_utc=utc_now())
        )
