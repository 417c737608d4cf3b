"""The one way in: the runs of any file tankdaq reads, the reader picked by the file's suffix.

As python-can's ``LogReader`` picks a reader class by suffix, ``INPUT_FORMATS`` maps a suffix to its
format (a reader and whether the file names its own test condition); ``read_runs(path)`` is the one entry
point for decays, and ``by_suffix`` the one suffix lookup (the AUV records of ``auv.io`` use it with
their own table): an unknown suffix gets one line listing the known ones. The store only reads: a plain
CSV comes back whole and ``ident.inputs.read_decays`` finds its releases on the way in.
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from ..errors import InputError
from ..records import DecayRun
from .csv_import import DEFAULT_CSV, CsvOptions, read_csv_file, runs_of_columns

if TYPE_CHECKING:
    from .export_layout import ExportOrigin

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
    """A CSV or text table; an Xsens MT Manager export (``store.mt_manager``) by its own reader."""
    from ..config.validation import input_file
    from .mt_manager import is_mt_manager, read_mt_manager

    input_file(path)
    if is_mt_manager(path):
        return runs_of_columns(path, read_mt_manager(path, options), options, axis)
    return read_csv_file(path, options, axis)


def _read_mtb(path: Path, axis: str | None, options: CsvOptions) -> list[DecayRun]:
    from .mtb_file import read_mtb

    return read_mtb(path, axis, options)


def _column_reader(name: str) -> Callable[[Path, str | None, CsvOptions], list[DecayRun]]:
    """The runs of a column file (``store.column_files``: HDF5, MATLAB, Parquet), read as a CSV's."""

    def read(path: Path, axis: str | None, options: CsvOptions) -> list[DecayRun]:
        from . import column_files

        found = getattr(column_files, name)(path, replace(options, axis=axis or options.axis))
        return runs_of_columns(path, found, options, axis)

    return read


#: The format name of tankdaq's own recordings (``InputFormat.name``; a recording's ``meta["format"]``).
RECORDING_FORMAT = "tankdaq recording"
#: Suffix (lower case) -> format. A column file's test condition comes from its metadata when
#: ``tankdaq export`` wrote it, else from its name or sidecar, as a CSV's.
INPUT_FORMATS: dict[str, InputFormat] = {
    ".mcap": InputFormat(RECORDING_FORMAT, _read_mcap, self_labelled=True),
    ".csv": InputFormat("CSV", _read_csv, self_labelled=False),
    ".txt": InputFormat("text table", _read_csv, self_labelled=False),  # MT Manager's default export
    ".h5": InputFormat("HDF5", _column_reader("read_h5_columns"), self_labelled=False),
    ".hdf5": InputFormat("HDF5", _column_reader("read_h5_columns"), self_labelled=False),
    ".mat": InputFormat("MATLAB", _column_reader("read_mat_columns"), self_labelled=False),
    ".parquet": InputFormat("Parquet", _column_reader("read_parquet_columns"), self_labelled=False),
    ".tdms": InputFormat("LabVIEW TDMS", _column_reader("read_tdms_columns"), self_labelled=False),
    ".mtb": InputFormat("MT Manager log", _read_mtb, self_labelled=False),
}


#: Spreadsheet workbooks: not read, but said to be what they are (a lab's first try is its Excel file).
WORKBOOKS = (".xlsx", ".xlsm", ".xls", ".ods", ".numbers")


def by_suffix(path: str | Path, table: Mapping[str, T], what: str = "decays") -> T:
    """``table``'s entry for the file's suffix; an unknown one is one line naming the known ones."""
    suffix = Path(path).suffix.lower()
    if suffix not in table:
        kind = suffix or "(no suffix)"
        if suffix in WORKBOOKS:
            kind += " (a spreadsheet workbook: save its sheet as CSV)"
        raise InputError(f"{path}: unknown file type {kind}; {what}: use a {suffixes(table)} file")
    return table[suffix]


def suffixes(table: Mapping[str, object]) -> str:
    """The suffixes of a table, as a line names them: ``.mcap, .csv or .h5``."""
    names = list(table)
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


def input_format(path: str | Path) -> InputFormat:
    """The format of a decay file, by its suffix."""
    return by_suffix(path, INPUT_FORMATS)


def read_runs(path: str | Path, axis: str | None = None, csv: CsvOptions = DEFAULT_CSV) -> list[DecayRun]:
    """The runs of one file as stored (a recording's decays from each release event; a CSV as
    ``csv_import.read_csv_file`` reads it). Without ``axis`` a recording is read on the axis it names,
    a CSV as roll. Each run's ``meta["sha256"]`` is the SHA-256 of the bytes read (so a fit is
    catalogued on the row of those bytes, not of whatever the path holds later); absent when the file
    changed while it was read."""
    path = Path(path)
    reader = input_format(path).read
    before = _identity(path)
    try:
        digest = file_sha256(path) if before is not None else None
    except OSError:  # unreadable: the reader says so in its own line
        digest = None
    runs = reader(path, axis, csv)
    if digest is not None and _identity(path) == before:
        for run in runs:
            run.meta["sha256"] = digest
    return runs


def _identity(path: Path) -> tuple[int, int, int] | None:
    """What changes when a file's bytes do (size, modification time, inode); None for no file."""
    try:
        found = path.stat()
    except OSError:
        return None
    return (found.st_size, found.st_mtime_ns, found.st_ino) if path.is_file() else None


def read_twice(
    paths: Sequence[Path],
    digests: Mapping[Path, str] | None = None,
    origins: Mapping[Path, ExportOrigin | None] | None = None,
) -> dict[Path, str]:
    """The files among ``paths`` whose decays another one among them holds already, each with why:
    a byte-for-byte copy of an earlier file (the same folder copied into a "selected" one), or an
    export of decays read from another file (``export_layout.exports_read_twice``). Read twice, a decay
    would count as two repeats and narrow every interval. ``digests`` and ``origins``: each file's
    SHA-256 and ``ExportOrigin`` where the caller has them (a campaign's workers find them as they
    scan); else only files of equal size are hashed, here, and the exports' metadata read."""
    from .export_layout import exports_read_twice

    twice = exports_read_twice(paths, origins)
    if digests is None:
        by_size: dict[int, list[Path]] = defaultdict(list)
        for path in paths:
            if path not in twice and path.is_file():
                by_size[path.stat().st_size].append(path)
        digests = {path: file_sha256(path) for group in by_size.values() if len(group) > 1 for path in group}
    first: dict[str, Path] = {}
    for path in paths:
        digest = digests.get(path)
        if path in twice or digest is None:
            continue
        if digest in first:
            twice[path] = f"holds the same bytes as {first[digest]}"
        else:
            first[digest] = path
    return twice


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes, in hex."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
