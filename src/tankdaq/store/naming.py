"""Recording file names a person can find, and files that are never overwritten.

A tank campaign produces hundreds of decays; the name says what a person looks
for first (hull, draft, axis, angle, when, which run). Files are created with
O_EXCL so two runs (or a rerun of a command) can never clobber a recording.
"""

from __future__ import annotations

import os
import re
from datetime import UTC, datetime
from pathlib import Path

from ..config import format_draft
from ..errors import RecordingError

_MAX_SUFFIX = 999


def _format_draft(draft: float | str) -> str:
    return draft if isinstance(draft, str) else format_draft(draft)


def _format_angle(angle_deg: float) -> str:
    return f"{abs(angle_deg):g}deg"


def _series_prefix(hull: str, draft: float | str, axis: str) -> str:
    return f"{hull}_{_format_draft(draft)}_{axis}_"


def recording_name(
    hull: str, draft: float | str, axis: str, angle_deg: float, run: int, when: datetime | None = None
) -> str:
    """``swath_1.1T_roll_8deg_20261121-143015_run03.mcap`` (time in UTC unless ``when`` says otherwise)."""
    stamp = (when or datetime.now(UTC)).strftime("%Y%m%d-%H%M%S")
    return f"{_series_prefix(hull, draft, axis)}{_format_angle(angle_deg)}_{stamp}_run{run:02d}.mcap"


def next_run_number(folder: str | Path, hull: str, draft: float | str, axis: str) -> int:
    """One more than the highest run number of this hull, draft and axis already in ``folder``."""
    pattern = re.compile(re.escape(_series_prefix(hull, draft, axis)) + r".*_run(\d+)(?:-\d+)?\.mcap$")
    folder = Path(folder)
    if not folder.is_dir():
        return 1
    runs = [int(m.group(1)) for p in folder.glob("*.mcap") if (m := pattern.match(p.name))]
    return max(runs, default=0) + 1


def candidate_paths(path: str | Path) -> list[Path]:
    """``path`` then ``stem-2.ext``, ``stem-3.ext`` ...: the names tried before giving up."""
    path = Path(path)
    suffix = "".join(path.suffixes[-1:])
    stem = path.name[: len(path.name) - len(suffix)] if suffix else path.name
    return [path] + [path.with_name(f"{stem}-{k}{suffix}") for k in range(2, _MAX_SUFFIX + 1)]


def create_exclusive(path: str | Path) -> tuple[Path, int]:
    """Create the first free name of ``candidate_paths(path)`` with O_EXCL; return it and its open fd.

    O_EXCL makes the check and the creation one step, so a file that appears
    between looking and writing is never overwritten.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise RecordingError(f"cannot create {path}: folder {path.parent} does not exist")
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for candidate in candidate_paths(path):
        try:
            return candidate, os.open(candidate, flags, 0o644)
        except FileExistsError:
            continue
        except OSError as exc:
            raise RecordingError(f"cannot create {candidate}: {exc.strerror}") from None
    raise RecordingError(f"cannot create {path}: {_MAX_SUFFIX} files of that name already exist")
