"""The journal of a guided session: ``session.jsonl``, its append-only log, written fsynced and read back
defensively, and ``session.lock``, which keeps a second session out of the folder.

The log is the session's only state, and it is a file on a lab disk: a power cut leaves half a line,
an editor or a copy can leave bytes that are not UTF-8 or lines that are not records. Reading it back
never fails on such a line: every line that cannot be used is skipped and listed (``SessionLog.skipped``,
one line each naming the line number and why), and the session goes on from the others. A decay whose
record was skipped is not lost: its file is still in the folder, and the session adopts it.

The lock is a ``flock`` on ``session.lock``: the kernel drops it when its process dies, so a stale lock
never blocks.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..errors import InputError, TankdaqError

LOG_NAME = "session.jsonl"
LOCK_NAME = "session.lock"
#: The verdicts a decay can have.
VERDICTS = ("accepted", "rejected")


class SessionLog:
    """``session.jsonl``: append-only, one JSON object per line, each fsynced before ``append`` returns.

    ``read()`` returns the records that can be used; ``skipped`` then lists the others, one line each
    (a line cut by a crash, bytes that are not UTF-8, JSON that is not a record or lacks what its
    type needs), and ``lines`` the line number of each record returned.
    """

    def __init__(self, folder: Path) -> None:
        self.path = folder / LOG_NAME
        self.skipped: list[str] = []
        self.lines: list[int] = []

    def exists(self) -> bool:
        return self.path.is_file() and self.path.stat().st_size > 0

    def read(self) -> list[dict[str, Any]]:
        self.skipped, self.lines = [], []
        if not self.path.is_file():
            return []
        records = []
        for number, raw in enumerate(self.path.read_bytes().split(b"\n"), 1):
            if not raw.strip():
                continue
            record, why = _parse_line(raw)
            if record is None:
                self.skipped.append(f"{self.path.name} line {number} skipped: {why}")
                continue
            records.append(record)
            self.lines.append(number)
        return records

    def append(self, kind: str, /, **fields: Any) -> dict[str, Any]:
        record = {"type": kind, "at": datetime.now(UTC).isoformat(timespec="milliseconds"), **fields}
        data = (json.dumps(record, default=str) + "\n").encode()
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            if os.lseek(fd, 0, os.SEEK_END) > 0 and not self._ends_with_newline():
                data = b"\n" + data  # after a line cut by a crash: start a fresh line
            os.write(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        return record

    def _ends_with_newline(self) -> bool:
        with self.path.open("rb") as fh:
            fh.seek(-1, os.SEEK_END)
            return fh.read(1) == b"\n"


def check_resumable(log: SessionLog, records: list[dict[str, Any]]) -> None:
    """``--resume`` needs a log that holds the session's plan (its first record): else one line naming
    what is wrong with the log and what to do (exit 2: nothing to resume; exit 1: the log is damaged)."""
    folder, name = log.path.parent, log.path.name
    if not log.path.is_file():
        raise InputError(f"no session to resume in {folder} ({name} is missing); start it without --resume")
    if not records and not log.skipped:
        raise InputError(
            f"no session to resume in {folder}: {name} is empty (a session stopped before its first "
            "line); start it without --resume, the recordings in the folder are kept"
        )
    if any(r.get("type") == "plan" for r in records):
        return
    why = log.skipped[0] if log.skipped else f"{name} line {log.lines[0]} is not the session's plan"
    raise TankdaqError(
        f"cannot resume {folder}: {name} has lost the session's plan ({why}); restore {name} from "
        "a backup, or start the session again with another --out (the recordings here are kept)"
    )


def _parse_line(raw: bytes) -> tuple[dict[str, Any] | None, str]:
    """The record on one line, or None and why it cannot be used."""
    try:
        record = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        return None, "not UTF-8 text"
    except (json.JSONDecodeError, RecursionError):
        return None, "not a whole JSON line (cut by a crash, or edited)"
    if not isinstance(record, dict):
        return None, f"a JSON {type(record).__name__}, not a record"
    why = record_problem(record)
    return (None, why) if why else (record, "")


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_file_name(value: object) -> bool:
    """A plain file name in the session folder (a path elsewhere is never followed)."""
    return (
        isinstance(value, str)
        and value not in ("", ".", "..")
        and not any(bad in value for bad in ("/", "\\", "\0"))
    )


#: What each record type needs to be used: field -> test, and what the test asks for.
_NEEDS: dict[str, dict[str, tuple[Any, str]]] = {
    "run": {
        "decay": (lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1, "a decay number"),
        "draft": (lambda v: isinstance(v, str), "a draft"),
        "angle_deg": (_is_number, "an angle"),
        "file": (_is_file_name, "a file name in the session folder"),
        "reasons": (
            lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
            "a list of reasons",
        ),
        "measured": (lambda v: isinstance(v, dict), "the measured values"),
    },
    "verdict": {
        "decay": (lambda v: isinstance(v, int) and not isinstance(v, bool), "a decay number"),
        "verdict": (lambda v: v in VERDICTS, "accepted or rejected"),
    },
    "skip": {"draft": (lambda v: isinstance(v, str), "a draft"), "angle_deg": (_is_number, "an angle")},
    "draft": {"draft": (lambda v: isinstance(v, str), "a draft")},
    "report": {"files": (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "file names")},
}


def record_problem(record: dict[str, Any]) -> str | None:
    """Why a record cannot be used (None: it can): each field its type needs, of the right kind."""
    kind = record.get("type")
    for name, (test, what) in _NEEDS.get(kind if isinstance(kind, str) else "", {}).items():
        if name not in record or not test(record[name]):
            return f"a {kind} record without {what} ({name})"
    return None


class SessionLock:
    """An exclusive ``flock`` on ``session.lock`` for as long as the session runs (context manager)."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / LOCK_NAME
        self._fd = -1

    def __enter__(self) -> SessionLock:
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise InputError(
                f"another session (pid {holder}) is writing {self.path.parent}; "
                "wait for it, or use another --out"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def __exit__(self, *exc: object) -> None:
        if self._fd >= 0:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = -1
