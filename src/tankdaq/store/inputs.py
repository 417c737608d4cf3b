"""The one way in: the runs of any file tankdaq reads, the reader picked by the file's suffix.

As python-can's ``LogReader`` picks a reader class by suffix, ``INPUT_FORMATS`` maps a suffix to its
format (a reader and whether the file names its own test condition); ``read_runs(path)`` is the one entry
point for decays, and ``by_suffix`` the one suffix lookup (the AUV records of ``maneuver.io`` use it with
their own table): an unknown suffix gets one line listing the known ones. The store only reads: a plain
CSV comes back whole and ``ident.inputs.read_decays`` finds its releases on the way in.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from ..errors import InputError
from ..records import DecayRun
from .csv_import import DEFAULT_CSV, CsvOptions, read_csv_file

T = TypeVar("T")


@dataclass(frozen=True)
class InputFormat:
    """A file format decays are read from."""

    name: str
    read: Callable[[Path, str | None, CsvOptions], list[DecayRun]]
    #: The file says hull, draft, axis and nominal angle itself (a recording's metadata); else they
    #: come from its name (``store.naming``) or a JSON sidecar.
    self_labelled: bool


def _read_mcap(path: Path, axis: str | None, _options: CsvOptions) -> list[DecayRun]:
    from .reader import read_decay_runs  # the MCAP stack only when a recording is read

    return read_decay_runs(path, axis)


def _read_csv(path: Path, axis: str | None, options: CsvOptions) -> list[DecayRun]:
    return read_csv_file(path, options, axis)


#: Suffix (lower case) -> format.
INPUT_FORMATS: dict[str, InputFormat] = {
    ".mcap": InputFormat("tankdaq recording", _read_mcap, self_labelled=True),
    ".csv": InputFormat("CSV", _read_csv, self_labelled=False),
}


def by_suffix(path: str | Path, table: Mapping[str, T], what: str = "decays") -> T:
    """``table``'s entry for the file's suffix; an unknown one is one line naming the known ones."""
    suffix = Path(path).suffix.lower()
    if suffix not in table:
        known = " or ".join(table)
        raise InputError(f"{path}: unknown file type {suffix or '(no suffix)'}; {what}: use a {known} file")
    return table[suffix]


def input_format(path: str | Path) -> InputFormat:
    """The format of a decay file, by its suffix."""
    return by_suffix(path, INPUT_FORMATS)


def read_runs(path: str | Path, axis: str | None = None, csv: CsvOptions = DEFAULT_CSV) -> list[DecayRun]:
    """The runs of one file as stored (a recording's decays from each release event; a CSV as
    ``csv_import.read_csv_file`` reads it). Without ``axis`` a recording is read on the axis it names,
    a CSV as roll."""
    return input_format(path).read(Path(path), axis, csv)
