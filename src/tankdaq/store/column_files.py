"""Decays from the column files other tools write: HDF5 (h5py), MATLAB (scipy.io; a v7.3 file is HDF5)
and Parquet (pyarrow, ``pip install 'tankdaq[parquet]'``).

A lab's archive keeps runs in these (SSPA's run database points at each run's HDF5 file), and
``tankdaq export`` writes them. Each reader gives what a CSV gives (``csv_import.ColumnData``): the
numeric columns of one length, what it left out, a ``tankdaq export``'s metadata, and the unit a column
states; ``csv_import.runs_of_columns`` then reads them exactly as a CSV's, so the columns, the units
decided from the data and every check are the same.

Columns are named as the file names them: an HDF5 dataset by its path (``roll`` at the root,
``run/roll`` in a group), a MATLAB variable by its name and a struct's field as ``s.roll`` (an export's
struct ``tankdaq`` by the field alone), a Parquet column by its name.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from ..config.validation import input_file
from ..errors import InputError, install_hint
from .csv_import import SPEED_CHANNEL, ColumnData, CsvOptions
from .csv_units import stated_unit
from .export_layout import EXPORT_FORMAT, mat_export_meta, plain_value
from .pandas_hdf import NOT_A_VECTOR, is_frame, is_pytables_index, read_frame

#: What a MATLAB v7.3 file (HDF5 with a 512-byte header) starts with.
MAT73_MARK = b"MATLAB 7.3 MAT-file"
#: The struct ``tankdaq export`` writes a .mat file's columns into.
EXPORT_STRUCT = "tankdaq"


def read_h5_columns(path: Path, options: CsvOptions) -> ColumnData:
    """The 1-D numeric datasets of an HDF5 file (and the fields of a 1-D table of records), their ``unit``
    attributes, the frames pandas wrote (``pandas_hdf``: named as pandas names their columns, with the
    frame's key in front where a file holds several), and the root attributes of a ``tankdaq export``."""
    h5py = _library(path, "h5py", "HDF5", "h5py")
    columns: dict[str, np.ndarray] = {}
    stated: dict[str, str] = {}
    left: dict[str, str] = {}
    said: list[str] = []
    apart: list[str] = []  # the groups of pandas frames and of PyTables' indexes: read apart, or not data

    def find_apart(name: str, node: Any) -> None:
        if isinstance(node, h5py.Group) and (is_frame(node) or is_pytables_index(node)):
            apart.append(name)

    def take(name: str, node: Any) -> None:
        if not isinstance(node, h5py.Dataset) or any(name.startswith(f"{group}/") for group in apart):
            return
        if node.dtype.names:  # a table of records: each numeric field a column
            if node.ndim == 1:
                for field in node.dtype.names:
                    _take(f"{name}/{field}", node[field], columns, left, said)
            else:
                left[name] = NOT_A_VECTOR
            return
        if node.dtype.kind not in "biuf" or len(node.shape) not in (1, 2) or node.size != max(node.shape):
            left[name] = NOT_A_VECTOR  # a matrix, a scalar or text (a vector is N, N x 1 or 1 x N)
        elif _take(name, node[()], columns, left, said):
            unit = stated_unit(node.attrs.get("unit", node.attrs.get("units")))
            if unit is not None:
                stated[name] = unit

    input_file(path)
    try:
        with h5py.File(path, "r") as h5:
            h5.visititems(find_apart)
            h5.visititems(take)
            frames = [read_frame(h5[name], name) for name in apart if is_frame(h5[name])]
            attrs = {key: plain_value(h5.attrs[key]) for key in h5.attrs}
    except OSError as exc:
        raise InputError(f"{path}: not an HDF5 file h5py can read ({exc})") from None
    for frame in frames:
        prefix = "" if len(frames) == 1 else f"{frame.key}/"
        columns |= {prefix + column: values for column, values in frame.columns.items()}
        left |= {prefix + column: why for column, why in frame.left.items()}
    header = attrs if attrs.get("format") == EXPORT_FORMAT else {}
    return _one_length(path, ColumnData(columns, left, header, stated, said), options, "datasets")


def read_mat_columns(path: Path, options: CsvOptions) -> ColumnData:
    """The numeric vectors of a MATLAB file (variables, and the fields of a struct), and the metadata of
    a ``tankdaq export``'s struct; a v7.3 file (HDF5) through ``read_h5_columns``, its fields named
    with a dot as MATLAB names them."""
    input_file(path)
    with path.open("rb") as fh:
        if fh.read(len(MAT73_MARK)) == MAT73_MARK:
            found = read_h5_columns(path, options)
            found.columns = {name.replace("/", "."): values for name, values in found.columns.items()}
            found.stated = {name.replace("/", "."): unit for name, unit in found.stated.items()}
            return found
    loadmat = _library(path, "scipy.io", "MATLAB", "scipy").loadmat
    try:
        variables = loadmat(path, simplify_cells=True)
    except Exception as exc:  # scipy fails in many ways on bytes that are no MATLAB file (IndexError...)
        raise InputError(f"{path}: not a MATLAB file scipy can read ({type(exc).__name__}: {exc})") from None
    columns: dict[str, np.ndarray] = {}
    left: dict[str, str] = {}
    said: list[str] = []
    header: dict[str, object] = {}
    for name, value in variables.items():
        if name.startswith("__"):
            continue
        if isinstance(value, dict):
            export = name == EXPORT_STRUCT and mat_export_meta(value.get("meta"))
            if export:
                header = export
            for field, inner in value.items():
                if not (export and field in ("meta", "units")):
                    _take(field if export else f"{name}.{field}", inner, columns, left, said)
        else:
            _take(name, value, columns, left, said)
    return _one_length(path, ColumnData(columns, left, header, notices=said), options, "variables")


def read_parquet_columns(path: Path, options: CsvOptions) -> ColumnData:
    """The numeric columns of a Parquet file, their fields' ``unit`` metadata, and the metadata of a
    ``tankdaq export`` (the JSON under the schema key ``tankdaq``)."""
    parquet = _library(path, "pyarrow.parquet", "Parquet", f"pyarrow: {install_hint('parquet')}")
    input_file(path)
    try:
        table = parquet.read_table(path)
    except Exception as exc:  # pyarrow's own errors (ArrowInvalid...), whatever the bytes were
        why = f"{type(exc).__name__}: {exc}"
        raise InputError(f"{path}: not a Parquet file pyarrow can read ({why})") from None
    columns: dict[str, np.ndarray] = {}
    stated: dict[str, str] = {}
    left: dict[str, str] = {}
    said: list[str] = []
    for field in table.schema:
        values = table.column(field.name).to_numpy(zero_copy_only=False)
        if _take(field.name, values, columns, left, said):
            unit = stated_unit((field.metadata or {}).get(b"unit"))
            if unit is not None:
                stated[field.name] = unit
    try:
        meta = json.loads((table.schema.metadata or {}).get(b"tankdaq", b"null"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        meta = None
    header = meta if isinstance(meta, dict) and meta.get("format") == EXPORT_FORMAT else {}
    return _one_length(path, ColumnData(columns, left, header, stated, said), options, "columns")


def _library(path: Path, module: str, kind: str, install: str) -> Any:
    """The library a file kind is read with; one line naming what to install where it is missing."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"{path}: reading a {kind} file needs {install}") from None


def _take(
    name: str, value: object, columns: dict[str, np.ndarray], left: dict[str, str], notices: list[str]
) -> bool:
    """A value as a column when it is a vector of numbers (a MATLAB column or row, N x 1 or 1 x N), or of
    times (pandas' timestamps: seconds from the first); else its name among those left out. True when
    taken."""
    array = np.asarray(value) if isinstance(value, np.ndarray | list) else None
    if array is not None and array.ndim == 2 and 1 in array.shape:
        array = array.reshape(-1)
    if array is not None and array.ndim == 1 and array.dtype.kind in "mM" and array.size:
        array = (array - array[0]) / np.timedelta64(1, "ns") * 1e-9  # NaT becomes NaN
        notices.append(f"column {name!r}: timestamps read as seconds from the first ({np.asarray(value)[0]})")
    if array is None or array.ndim != 1 or array.dtype.kind not in "biuf" or array.size == 0:
        left[name] = NOT_A_VECTOR
        return False
    columns[name] = array.astype(float) if array.dtype.kind == "b" else array
    return True


def read_tdms_columns(path: Path, options: CsvOptions) -> ColumnData:
    """The numeric channels of a LabVIEW TDMS file (npTDMS), each named ``GROUP/CHANNEL``, with the unit
    its ``unit_string`` property states; without a time channel (``--time-col``), the time of the angle
    channel's waveform (``wf_start_offset`` + i * ``wf_increment``, in s). The file's properties and the
    waveform's start time are kept in the header, as ``tdms_<property>``."""
    nptdms = _library(path, "nptdms", "TDMS", "npTDMS: pip install npTDMS")
    input_file(path)
    try:
        tdms = nptdms.TdmsFile.read(path)
    except Exception as exc:  # npTDMS' own errors (ValueError, struct.error...), whatever the bytes were
        raise InputError(f"{path}: not a TDMS file npTDMS can read ({type(exc).__name__}: {exc})") from None
    columns: dict[str, np.ndarray] = {}
    stated: dict[str, str] = {}
    left: dict[str, str] = {}
    said: list[str] = []
    properties: dict[str, dict[str, Any]] = {}
    for group in tdms.groups():
        for channel in group.channels():
            name = f"{group.name}/{channel.name}"
            properties[name] = dict(channel.properties)
            if _take(name, channel[:], columns, left, said):
                unit = stated_unit(channel.properties.get("unit_string"))
                if unit is not None:
                    stated[name] = unit
    header = {f"tdms_{key}": _plain(value) for key, value in tdms.properties.items()}
    angle_col = options.angle_col
    if angle_col == CsvOptions.angle_col and angle_col not in columns:  # none named: the one whose name says
        # the axis (Roll); a channel the user named and the file lacks is refused, never replaced
        angle_col = _named_channel(columns, (options.axis,), angle_col, said)
    elif angle_col not in columns:
        names = ", ".join(columns) or "none with numbers"
        raise InputError(f"{path}: no channel {angle_col!r}; it has {names} (--angle-col GROUP/NAME)")
    if angle_col != options.angle_col:
        columns[options.angle_col] = columns.pop(angle_col)
        if angle_col in stated:
            stated[options.angle_col] = stated.pop(angle_col)
    if options.speed_col is None and SPEED_CHANNEL not in columns:
        speed = _named_channel(columns, ("speed",), "", said)
        if speed:
            columns[SPEED_CHANNEL] = columns.pop(speed)
    wave = properties.get(angle_col, {})
    if options.time_col not in columns and "wf_increment" in wave and options.angle_col in columns:
        step, start = float(wave["wf_increment"]), float(wave.get("wf_start_offset", 0.0))
        columns[options.time_col] = start + step * np.arange(len(columns[options.angle_col]))
        stated[options.time_col] = "s"
        said.append(f"time from {angle_col}'s waveform: {step:g} s a sample")
        if "wf_start_time" in wave:
            header["tdms_wf_start_time"] = _plain(wave["wf_start_time"])
    return _one_length(path, ColumnData(columns, left, header, stated, said), options, "channels")


def _named_channel(
    columns: dict[str, np.ndarray], words: tuple[str, ...], given: str, said: list[str]
) -> str:
    """The one channel whose own name (after ``GROUP/``) is one of ``words`` or starts with one (``Roll``,
    ``roll_deg``, ``Speed``), said in a line; ``given`` where none or several are."""
    found = [
        name for name in columns if any(name.rpartition("/")[2].lower().startswith(word) for word in words)
    ]
    if len(found) != 1:
        return given
    said.append(f"channel {found[0]} read as the {words[0]} (its name says so)")
    return found[0]


def _plain(value: object) -> object:
    """A TDMS property as JSON keeps it (a number, or text: a timestamp in ISO form)."""
    if isinstance(value, np.datetime64):
        return str(value)
    if isinstance(value, np.generic):
        value = value.item()
    return value if isinstance(value, int | float | str) else str(value)


def _one_length(path: Path, data: ColumnData, options: CsvOptions, what: str) -> ColumnData:
    """The columns of the record the time column belongs to (the most common length without one); those
    of another length, and what was not a vector of numbers, said in one line."""
    data.notices = [f"{path.name}: {line}" for line in data.notices]
    if not data.columns:
        why = [f"{name} {reason}" for name, reason in data.ignored.items() if reason != NOT_A_VECTOR][:2]
        said = f" ({'; '.join(why)})" if why else ""
        raise InputError(
            f"{path}: no {what} that are vectors of numbers{said}; a decay needs a time and an angle column"
        )
    lengths = Counter(len(values) for values in data.columns.values())
    time = data.columns.get(options.time_col)
    rows = len(time) if time is not None else lengths.most_common(1)[0][0]
    other = [name for name, values in data.columns.items() if len(values) != rows]
    data.columns = {name: values for name, values in data.columns.items() if len(values) == rows}
    plain = [name for name, why in data.ignored.items() if why == NOT_A_VECTOR]
    if plain:
        data.notices.append(f"{path.name}: {what} not read (not vectors of numbers): {_names(plain)}")
    data.notices += [
        f"{path.name}: {name} not read: it {why}" for name, why in data.ignored.items() if why != NOT_A_VECTOR
    ]
    if other:
        longer = f"is not {rows} values long, as {options.time_col!r} is" if time is not None else None
        data.notices.append(f"{path.name}: {what} not read (not {rows} values long): {_names(other)}")
        data.ignored |= dict.fromkeys(other, longer or f"is not {rows} values long, as most are")
    return data


def _names(names: list[str]) -> str:
    """Up to eight names, then how many more."""
    more = f" and {len(names) - 8} more" if len(names) > 8 else ""
    return ", ".join(names[:8]) + more
