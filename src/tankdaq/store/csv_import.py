"""Records from CSV files (other labs' data, spreadsheets, the KVLCC2 reference run), read as stored.

The store only reads. A file written by ``tankdaq export`` (``store.export``) is read back exactly: its
``<stem>.json`` sidecar (``store.export_layout``) becomes ``meta``, the axis' SI columns (``roll_rad``,
``p_rad_s``) are taken without a ``--angle-col``, and its ``release_t_s`` cuts the runs where the
recording did. An export written before the sidecar (a ``# key = value`` block, ``angle_rad`` and
``rate_rad_s``, a units row) is read the same way. Any
other CSV comes back whole, as one record marked ``meta[FIND_RELEASES]``: where its decays start (one or
several releases in a long record) is found by ``ident.inputs`` on the way in, since finding a release is
signal work of identification (noise levels, where a free decay ends) and data flows one way, store ->
ident, never back. Extra numeric columns become ``DecayRun.channels`` in SI units (``*_deg`` columns are
converted to rad and lose the suffix, so ``other_angle_deg`` -> ``other_angle``).

Any dialect a spreadsheet writes is read (``store.csv_dialect``: BOM, comma, semicolon or tab, decimal
commas, CRLF, text columns left out), and the angle and time units are decided from the data where not
given (``store.csv_units``); what was decided travels with the runs as one line each (``meta[NOTICES]``).
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config.validation import input_file
from ..errors import BadIdentificationInput, InputError
from ..records import DecayRun
from .csv_dialect import CsvTable, read_table
from .csv_units import ANGLE_UNITS, TIME_UNITS, UnitChoice, angle_unit, time_unit
from .export_layout import axis_columns, read_sidecar, sidecar_path
from .orientation_columns import find_orientation, refuse_component

#: A decay needs at least this many samples.
MIN_SAMPLES = 20
#: The rate column looked for by default; any other name given must exist.
DEFAULT_RATE_COL = "rate_deg_s"
#: The first line of a CSV exported before the JSON sidecar (a ``# key = value`` metadata block).
EXPORT_MARK = "# tankdaq export"
#: ``meta`` key of a record read whole whose releases are still to be found (``ident.inputs``).
FIND_RELEASES = "find_releases"
#: ``meta`` key of the lines a reader has for the user (dialect, units decided from the data, parts
#: of the file not used): the commands print them, once per file.
NOTICES = "notices"
#: ``meta`` keys of what a file's own header says of the device and the tool that wrote it (an MT Manager
#: export's ``//`` block): kept with each run, shown by ``identify --json`` and ``tankdaq.read``.
SOURCE_KEYS = (
    "source_format", "device_id", "product_code", "firmware", "hardware", "filter_profile", "option_flags",
    "mt_manager_version", "xda_version", "coordinate_system", "start_time", "update_rate_hz",
)  # fmt: skip
#: The channel a ``--speed-col`` becomes (m/s), and the ``meta`` key naming the column it came from: each
#: decay's mean of it is its ``speed_m_s`` (``ident.inputs``).
SPEED_CHANNEL = "carriage_speed_m_s"
SPEED_FROM = "speed_from"


@dataclass(frozen=True)
class CsvOptions:
    """How to read other labs' CSV: the columns, the units (None: decided from the data,
    ``store.csv_units``), and ``keep_all`` (the record whole from its first sample: no cut at its
    releases)."""

    time_col: str = "time_s"
    angle_col: str = "angle_deg"
    rate_col: str | None = DEFAULT_RATE_COL
    angle_unit: str | None = None
    keep_all: bool = False
    time_unit: str | None = None
    #: Samples per second of a file that does not say (an MT Manager 2019.2+ export without
    #: SampleTimeFine): ``--rate``.
    sample_rate_hz: float | None = None
    #: the device of an MT Manager log that holds several (hex device id or bus id; None: each one a run)
    device: str | None = None
    #: a carriage-speed column (m/s): each decay's mean speed goes into its metadata (``speed_m_s``)
    speed_col: str | None = None
    #: the decay's axis, for a reader that finds the angle by a channel's name (TDMS: ``Roll``)
    axis: str = "roll"

    def __post_init__(self) -> None:  # checked whatever the files are: a typo fails on a recording too
        if self.angle_unit not in (None, *ANGLE_UNITS):
            raise InputError(f"angle unit {self.angle_unit!r} not understood: use deg or rad")
        if self.time_unit not in (None, *TIME_UNITS):
            raise InputError(f"time unit {self.time_unit!r} not understood: use s, ms or tick (0.1 ms)")
        rate = self.sample_rate_hz
        if rate is not None and not (isinstance(rate, int | float) and 0.1 <= rate <= 100_000):
            raise InputError(f"--rate {rate!r}: give the file's sample rate in Hz, 0.1 to 100000")


DEFAULT_CSV = CsvOptions()


def read_csv_file(
    path: str | Path, options: CsvOptions = DEFAULT_CSV, axis: str | None = None
) -> list[DecayRun]:
    """The runs of a CSV file as stored: an export's runs from each recorded release, else the record
    whole (marked ``FIND_RELEASES`` unless ``keep_all``); without the rate column the angle is the only
    output. ``axis`` None: an export's own axis, else roll. What the reader decided (dialect, units) is
    in ``meta[NOTICES]``."""
    path = Path(path)
    table, header = _read_columns(path, options)
    notices = [f"{path.name}: read as {table.dialect.describe()}"] if not table.dialect.plain else []
    if table.ignored:
        notices.append(f"{path.name}: text columns not read: {', '.join(table.ignored)}")
    found = ColumnData(table.columns, dict.fromkeys(table.ignored, "holds text"), header, notices=notices)
    return runs_of_columns(path, found, options, axis)


@dataclass
class ColumnData:
    """What a file's reader found: its numeric columns by name (each one value per row), the columns it
    left out and why (``holds text``), a ``tankdaq export``'s metadata (else empty), the unit the file
    states for a column (an HDF5 ``unit`` attribute: read as a name's unit suffix is), and its lines
    for the user."""

    columns: dict[str, np.ndarray]
    ignored: dict[str, str]
    header: dict[str, object]
    stated: dict[str, str] = field(default_factory=dict)
    notices: list[str] = field(default_factory=list)


def runs_of_columns(
    path: Path, data: ColumnData, options: CsvOptions = DEFAULT_CSV, axis: str | None = None
) -> list[DecayRun]:
    """The runs of a file's columns (a CSV's, or another column file's: ``store.column_files``), as
    ``read_csv_file`` makes them."""
    columns, header = dict(data.columns), data.header
    rows = len(next(iter(columns.values()))) if columns else 0
    if rows < MIN_SAMPLES:
        raise BadIdentificationInput(f"{path}: {rows} data rows; a decay needs at least {MIN_SAMPLES}")
    if axis is None and "axis" in header and header["axis"] not in ("roll", "pitch"):
        raise InputError(
            f"{path}: its metadata says axis {json.dumps(header['axis'])[:40]}: fix it to roll or pitch, or "
            "give --axis"
        )
    axis = axis or str(header.get("axis", "roll"))
    if axis not in ("roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
    angle_col, given_unit, rate_col = options.angle_col, options.angle_unit, options.rate_col
    si_columns = ("angle_rad", "rate_rad_s")  # an export's angle and rate; before the sidecar: these
    if header and axis_columns(axis)[0] in columns:
        si_columns = axis_columns(axis)
    if angle_col == "angle_deg" and "angle_deg" not in columns and si_columns[0] in columns:  # SI (export)
        angle_col, given_unit = si_columns[0], "rad"
        rate_col = si_columns[1] if rate_col == DEFAULT_RATE_COL else rate_col
    if options.speed_col is not None and options.speed_col not in columns:
        raise InputError(f"{path}: no speed column {options.speed_col!r}; columns are {', '.join(columns)}")
    notices = list(data.notices)
    angle_col, given_unit = _orientation(path, data, axis, angle_col, given_unit, notices)
    _check_columns(path, data, options.time_col, angle_col, rate_col)
    columns = dict(data.columns)
    t_raw, angle_raw = columns.pop(options.time_col), columns.pop(angle_col)
    said = data.stated
    if header and angle_col == si_columns[0] and options.time_col == "time_s":  # an export says its units
        units = (UnitChoice("rad"), UnitChoice("s"))
    else:
        units = (
            angle_unit(angle_col, angle_raw, given_unit, said.get(angle_col)),
            time_unit(options.time_col, t_raw, angle_raw, options.time_unit, said.get(options.time_col)),
        )
    notices += [f"{path.name}: {choice.line}" for choice in units if choice.line]
    to_rad, to_s = ANGLE_UNITS[units[0].unit], TIME_UNITS[units[1].unit]
    rate = columns.pop(rate_col) * to_rad if rate_col is not None and rate_col in columns else None
    if options.speed_col is not None:
        columns[SPEED_CHANNEL] = columns.pop(options.speed_col)  # found by ``_check_columns``
    channels = {_channel_name(name): _to_si(name, values) for name, values in columns.items()}
    run = DecayRun(
        t=t_raw * to_s,
        angle=angle_raw * to_rad,
        rate=rate,
        axis=axis,
        name=path.stem,
        channels=channels,
        meta={"file": str(path)},
    )
    run.meta.update({key: value for key, value in header.items() if key != "units"})
    run.meta[NOTICES] = notices
    if options.speed_col is not None:
        run.meta[SPEED_FROM] = options.speed_col
    _check_motion(run, units[0].unit)
    if options.keep_all:
        return [run]
    releases = _release_times(path, header["release_t_s"]) if "release_t_s" in header else []
    if releases:
        return _exported_releases(run, releases)
    run.meta[FIND_RELEASES] = True
    return [run]


def _orientation(
    path: Path, data: ColumnData, axis: str, angle_col: str, given_unit: str | None, notices: list[str]
) -> tuple[str, str | None]:
    """The angle column and its unit: a quaternion or matrix component given is refused; without an
    angle column (the default ``angle_deg`` absent) the axis' angle from the file's orientation columns
    (``store.orientation_columns``: Euler as written, else converted, put in ``data.columns``)."""
    refuse_component(path, angle_col, axis)
    if angle_col != "angle_deg" or angle_col in data.columns:
        return angle_col, given_unit
    found = find_orientation(data.columns, axis)
    if found is None and str(data.header.get("source_format", "")).startswith("MT Manager"):  # no orientation
        raise InputError(
            f"{path}: no orientation in this {data.header['source_format']} (Roll/Pitch/Yaw, Euler_X..Z, a "
            "whole Quat_q0..q3 or Mat[1][1]..Mat[3][3]): export it with the orientation, or give --angle-col"
        )
    if found is None:
        return angle_col, given_unit
    notices.append(f"{path.name}: {found.line}")
    if found.angle_rad is None:
        return str(found.column), given_unit
    name = f"{axis}_from_orientation"
    data.columns[name] = found.angle_rad
    return name, "rad"


def source_facts(meta: dict[str, object]) -> dict[str, object]:
    """What a run's file header said of its device and tool (``SOURCE_KEYS``), as found."""
    return {key: meta[key] for key in SOURCE_KEYS if key in meta}


def _check_columns(path: Path, data: ColumnData, time_col: str, angle_col: str, rate_col: str | None) -> None:
    """The columns asked for exist, are numbers, and are not the same column twice."""
    columns = data.columns
    for label, name in (("time", time_col), ("angle", angle_col)):
        if name not in columns:
            why = data.ignored.get(name)
            what = f"the {label} column {name!r} {why}" if why else f"no {label} column {name!r}"
            raise InputError(
                f"{path}: {what}; numeric columns are {', '.join(columns)} (choose with --{label}-col)"
            )
    if time_col == angle_col:
        raise InputError(f"{path}: --time-col and --angle-col both name {time_col!r}: give two columns")
    if rate_col not in (None, DEFAULT_RATE_COL, "rate_rad_s") and rate_col not in columns:
        raise InputError(f"{path}: no rate column {rate_col!r}; columns are {', '.join(columns)}")
    if rate_col in (time_col, angle_col):
        raise InputError(f"{path}: --rate-col {rate_col!r} is the time or angle column: give another one")


def _release_times(path: Path, value: object) -> list[float]:
    """An export's ``release_t_s``: a list of finite times, increasing (else one line naming it)."""
    if isinstance(value, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        times = [float(v) for v in value]
        if times == sorted(times):
            return times
    where = "its metadata line" if path.suffix.lower() == ".csv" else "its metadata"
    where = sidecar_path(path).name if read_sidecar(path) is not None else where
    raise InputError(
        f"{path}: release_t_s = {json.dumps(value)[:60]} in {where} is not a list of increasing times "
        "in s; fix or delete it"
    )


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


def _read_columns(path: Path, options: CsvOptions) -> tuple[CsvTable, dict[str, object]]:
    """The numeric columns, and the metadata of a ``tankdaq export`` file: its JSON sidecar, or the
    ``# key = value`` block of an export written before the sidecar."""
    input_file(path)
    wanted = [options.time_col, options.angle_col]
    wanted += [options.rate_col] if options.rate_col not in (None, DEFAULT_RATE_COL) else []
    sidecar = read_sidecar(path)
    with path.open("rb") as fh:
        exported = fh.read(len(EXPORT_MARK) + 3).lstrip(b"\xef\xbb\xbf").startswith(EXPORT_MARK.encode())
    table = read_table(path, wanted, skip_rows=1 if exported else 0)  # an old export's units row
    header = sidecar if sidecar is not None else _metadata(table.comments) if exported else {}
    return table, header


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
