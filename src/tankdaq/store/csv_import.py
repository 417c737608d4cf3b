"""Records from CSV files (other labs' data, spreadsheets, the KVLCC2 reference run), read as stored.

The store only reads. A file written by ``tankdaq export`` (``store.export``) is read back exactly: SI
columns (``angle_rad``, ``rate_rad_s``) are taken without a ``--angle-col``, the units row is skipped, the
``# key = value`` block becomes ``meta`` and its ``release_t_s`` cuts the runs where the recording did. Any
other CSV comes back whole, as one record marked ``meta[FIND_RELEASES]``: where its decays start (one or
several releases in a long record) is found by ``ident.inputs`` on the way in, since finding a release is
signal work of identification (noise levels, where a free decay ends) and data flows one way, store ->
ident, never back. Extra numeric columns become ``DecayRun.channels`` in SI units (``*_deg`` columns are
converted to rad and lose the suffix, so ``other_angle_deg`` -> ``other_angle``).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadIdentificationInput, InputError
from ..records import DecayRun
from ..validation import input_file

ANGLE_UNITS: dict[str, float] = {"deg": math.pi / 180.0, "rad": 1.0}
#: A decay needs at least this many samples.
MIN_SAMPLES = 20
#: The rate column looked for by default; any other name given must exist.
DEFAULT_RATE_COL = "rate_deg_s"
#: The first line of a ``tankdaq export`` CSV (``store.export.CSV_MARK``).
EXPORT_MARK = "# tankdaq export"
#: ``meta`` key of a record read whole whose releases are still to be found (``ident.inputs``).
FIND_RELEASES = "find_releases"


@dataclass(frozen=True)
class CsvOptions:
    """How to read other labs' CSV: the columns, the angle unit, and ``keep_all`` (the record whole from
    its first sample: no cut at its releases)."""

    time_col: str = "time_s"
    angle_col: str = "angle_deg"
    rate_col: str | None = DEFAULT_RATE_COL
    angle_unit: str = "deg"
    keep_all: bool = False


DEFAULT_CSV = CsvOptions()


def read_csv_file(path: str | Path, options: CsvOptions = DEFAULT_CSV, axis: str = "roll") -> list[DecayRun]:
    """The runs of a CSV file as stored: an export's runs from each recorded release, else the record
    whole (marked ``FIND_RELEASES`` unless ``keep_all``); without the rate column the angle is the only
    output."""
    path = Path(path)
    angle_col, angle_unit, rate_col = options.angle_col, options.angle_unit, options.rate_col
    if angle_unit not in ANGLE_UNITS:
        raise InputError(f"angle unit {angle_unit!r} not understood: use deg or rad")
    if axis not in ("roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
    columns, header = _read_columns(path)
    if angle_col == "angle_deg" and "angle_deg" not in columns and "angle_rad" in columns:  # SI (export)
        angle_col, angle_unit = "angle_rad", "rad"
        rate_col = "rate_rad_s" if rate_col == DEFAULT_RATE_COL else rate_col
    for label, name in (("time", options.time_col), ("angle", angle_col)):
        if name not in columns:
            raise InputError(
                f"{path}: no {label} column {name!r}; columns are {', '.join(columns)} "
                f"(choose with --{label}-col)"
            )
    if rate_col not in (None, DEFAULT_RATE_COL, "rate_rad_s") and rate_col not in columns:
        raise InputError(f"{path}: no rate column {rate_col!r}; columns are {', '.join(columns)}")
    to_rad = ANGLE_UNITS[angle_unit]
    t = columns.pop(options.time_col)
    angle = columns.pop(angle_col) * to_rad
    rate = columns.pop(rate_col) * to_rad if rate_col is not None and rate_col in columns else None
    channels = {_channel_name(name): _to_si(name, values) for name, values in columns.items()}
    run = DecayRun(
        t=t, angle=angle, rate=rate, axis=axis, name=path.stem, channels=channels, meta={"file": str(path)}
    )
    run.meta.update(header)
    _check_motion(run, angle_unit)
    if options.keep_all:
        return [run]
    releases = header.get("release_t_s")
    if isinstance(releases, list) and releases:
        return _exported_releases(run, [float(r) for r in releases])
    run.meta[FIND_RELEASES] = True
    return [run]


def _exported_releases(record: DecayRun, releases: list[float]) -> list[DecayRun]:
    """The runs of an exported recording: from each release to the next, as ``store.reader`` cuts (and
    names) them."""
    starts = np.searchsorted(record.t, [*releases, math.inf], side="left")
    runs = [record.window(int(a), int(b)) for a, b in itertools.pairwise(starts)]
    return number_parts(runs)


def number_parts(runs: list[DecayRun]) -> list[DecayRun]:
    """Several runs of one file are named ``stem#1``, ``stem#2`` ... (one run keeps the stem)."""
    if len(runs) > 1:
        for number, run in enumerate(runs, start=1):
            run.name = f"{run.name}#{number}"
    return runs


def _read_columns(path: Path) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """The numeric columns, and the ``# key = value`` metadata block of a ``tankdaq export`` file."""
    input_file(path)
    try:
        with path.open(newline="") as fh:
            lines = [line for line in fh if line.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as CSV text ({exc})") from None
    header = _metadata(lines) if lines and lines[0].startswith(EXPORT_MARK) else {}
    rows = list(csv.reader(line for line in lines if not line.startswith("#")))
    if len(rows) > 1 and header and not _numeric(rows[1]):
        del rows[1]  # the units row of an export
    if len(rows) < 1 + MIN_SAMPLES:
        raise BadIdentificationInput(
            f"{path}: {max(len(rows) - 1, 0)} data rows; a decay needs at least {MIN_SAMPLES}"
        )
    names = [name.strip() for name in rows[0]]
    try:
        data = np.array([[float(cell) if cell.strip() else math.nan for cell in row] for row in rows[1:]])
    except ValueError as exc:
        raise InputError(f"{path}: a value is not a number ({exc}); only numeric columns are read") from None
    if data.ndim != 2 or data.shape[1] != len(names):
        raise InputError(f"{path}: rows have a different number of fields from the header")
    return {name: data[:, i] for i, name in enumerate(names)}, header


def _metadata(lines: list[str]) -> dict[str, object]:
    """``# key = <JSON>`` comment lines; a value that is not JSON stays text."""
    meta: dict[str, object] = {}
    for line in lines:
        if not line.startswith("#"):
            break
        key, sep, value = line[1:].partition(" = ")
        if sep:
            try:
                meta[key.strip()] = json.loads(value)
            except json.JSONDecodeError:
                meta[key.strip()] = value.strip()
    return meta


def _numeric(row: list[str]) -> bool:
    try:
        [float(cell) for cell in row if cell.strip()]
    except ValueError:
        return False
    return True


def _channel_name(column: str) -> str:
    for suffix in ("_deg", "_rad"):
        if column.endswith(suffix):
            return column[: -len(suffix)]
    return column


def _to_si(column: str, values: np.ndarray) -> np.ndarray:
    return values * ANGLE_UNITS["deg"] if column.endswith("_deg") else values


def _check_motion(run: DecayRun, angle_unit: str) -> None:
    """An axis that does not move gives a clear message instead of a failed fit."""
    span_deg = math.degrees(float(np.ptp(run.angle)))
    if span_deg < 0.05:
        raise BadIdentificationInput(
            f"{run.name}: the {run.axis} angle does not move (range {span_deg:.3g} deg); "
            f"wrong axis or wrong column? (angle unit {angle_unit})"
        )
