"""What a report reads: recordings given by path or glob (folders searched), a guided session's
folder (its accepted decays, as its own report takes them), or the catalogue's ``--runs`` query (with
each recording's catalogue id for the provenance). Found before any file is read."""

from __future__ import annotations

import glob
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..records import Verdict

#: What makes a path given a pattern to expand (when no file has that very name).
GLOB_CHARACTERS = frozenset("*?[")


@dataclass(frozen=True)
class ReportInputs:
    """The files to read, their catalogue ids (``--runs``: resolved path -> id), the session folders
    among the inputs, and the lines that say what was found."""

    files: list[Path]
    catalogue_ids: dict[Path, int] = field(default_factory=dict)
    sessions: list[Path] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)


def report_inputs(paths: Sequence[Path], runs: str | None, catalogue: str | None) -> ReportInputs:
    """The files of ``paths`` (files, folders, globs, session folders) or of the ``runs`` query (one of
    the two), each once."""
    if paths and runs:
        raise InputError("give recordings or --runs QUERY (runs=), not both")
    if runs:
        from ..catalogue.query import rows_for

        rows = rows_for(runs, catalogue)
        ids = {Path(row["path"]).resolve(): int(row["id"]) for row in rows}
        return ReportInputs(
            [Path(row["path"]) for row in rows], ids, [], [f"--runs: {len(rows)} recording(s)"]
        )
    if not paths:
        raise InputError('give recordings, a session folder or --runs "hull=NAME ..." (docs/report.md)')
    files: list[Path] = []
    sessions: list[Path] = []
    lines: list[str] = []
    for given in paths:
        for path in _expanded(given):
            if (path / "session.jsonl").is_file():
                accepted = session_files(path)
                sessions.append(path)
                lines.append(f"session {path}: {len(accepted)} accepted decay(s)")
                files += accepted
            else:
                from ..campaign.groups import find_recordings

                files += find_recordings([path])
    once = list(dict.fromkeys(files))
    return ReportInputs(once, {}, sessions, lines)


def _expanded(path: Path) -> list[Path]:
    """A path as given, or the files its pattern matches (sorted) when it names no file itself."""
    if path.exists() or not GLOB_CHARACTERS & set(str(path)):
        return [path]
    matched = sorted(Path(p) for p in glob.glob(str(path), recursive=True))
    if not matched:
        raise InputError(f"{path}: no file matches this pattern")
    return matched


def session_files(folder: Path) -> list[Path]:
    """The accepted decays of a guided session (its log, ``session.jsonl``), in the order recorded."""
    from ..config.rules import path_in
    from ..session.journal import SessionLog
    from ..session.state import SessionState

    state = SessionState.from_log(SessionLog(folder).read(), [], 0)
    accepted = [path_in(folder, run.file) for run in state.runs if run.verdict == Verdict.ACCEPTED]
    if not accepted:
        raise InputError(f"session {folder}: no decay accepted yet; nothing to report")
    gone = [path for path in accepted if not path.is_file()]
    if gone:
        raise InputError(
            f"session {folder}: {gone[0].name} is gone from the folder; resume the session first"
        )
    return accepted
