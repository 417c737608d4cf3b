"""Recording file names a person can find, and files that are never overwritten.

A tank campaign produces hundreds of decays; the name says what a person looks
for first (hull, draft, axis, angle, when, which run). The grammar is written
once, here, and read back here too (``parse_recording_name``: a campaign labels
CSV files named like recordings by it). Files are created with O_EXCL so two
runs (or a rerun of a command) can never clobber a recording.
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from ..config.hulls import format_draft, parse_draft
from ..config.rules import safe_name
from ..errors import RecordingError

_MAX_SUFFIX = 999
_STAMP_FORMAT = "%Y%m%d-%H%M%S"
#: ``hull_draft_axis_<angle>deg[_<stamp>][_run<NN>[-<k>]]``, then anything (a suffix, a note): the
#: name ``recording_name`` writes, read back. A shorter hand-made name (``trimaran_0.9T_pitch_8deg``)
#: has the same head.
NAME_GRAMMAR = re.compile(
    r"^(?P<hull>.+?)_(?P<draft>\d*\.?\d*T)_(?P<axis>roll|pitch)_(?P<angle>\d+(?:\.\d+)?)deg"
    r"(?:_(?P<stamp>\d{8}-\d{6}))?(?:_run(?P<run>\d+)(?:-\d+)?)?(?:[_.]|$)"
)


@dataclass(frozen=True)
class RecordingLabels:
    """What a recording's name says: the test condition, and when and which run when it has them."""

    hull: str
    draft: float  # factor of the design draft
    axis: str
    angle_deg: float
    stamp: str | None = None  # UTC, as recording_name writes it
    run: int | None = None


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
    safe_name(hull, "hull name")  # checked as the hull was loaded: a second line of defence
    stamp = (when or datetime.now(UTC)).strftime(_STAMP_FORMAT)
    return f"{_series_prefix(hull, draft, axis)}{_format_angle(angle_deg)}_{stamp}_run{run:02d}.mcap"


def parse_recording_name(name: str) -> RecordingLabels | None:
    """The labels in a file name (or stem) written in the recording grammar; None when it is not (a
    draft outside 0.3T..2.0T raises ``InputError``, as ``parse_draft`` does)."""
    match = NAME_GRAMMAR.match(name)
    if match is None:
        return None
    return RecordingLabels(
        hull=match["hull"],
        draft=parse_draft(match["draft"]),
        axis=match["axis"],
        angle_deg=float(match["angle"]),
        stamp=match["stamp"],
        run=None if match["run"] is None else int(match["run"]),
    )


def next_run_number(folder: str | Path, hull: str, draft: float | str, axis: str) -> int:
    """One more than the highest run number of this hull, draft and axis already in ``folder``."""
    folder = Path(folder)
    if not folder.is_dir():
        return 1
    prefix = _series_prefix(hull, draft, axis)
    runs = [
        labels.run
        for path in folder.glob(f"{glob.escape(prefix)}*.mcap")
        if (labels := parse_recording_name(path.name)) is not None and labels.run is not None
    ]
    return max(runs, default=0) + 1


def candidate_paths(path: str | Path) -> Iterator[Path]:
    """``path`` then ``stem-2.ext``, ``stem-3.ext`` ...: the names tried before giving up, made as they
    are tried (all 999 at once were 0.5 MB of Paths, their parts interned, at every file a recorder made)."""
    path = Path(path)
    suffix = "".join(path.suffixes[-1:])
    stem = path.name[: len(path.name) - len(suffix)] if suffix else path.name
    yield path
    for k in range(2, _MAX_SUFFIX + 1):
        yield path.with_name(f"{stem}-{k}{suffix}")


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
