"""Recordings out to other labs' tools: CSV (spreadsheets, ``tankdaq identify``) and MATLAB .mat.

One table per recording: time, the decay axis' angle and rate, then every other
recorded sample field, all in SI units, with the run metadata (a ``# key = value``
comment block in CSV, a ``meta`` struct in .mat). ``release_t_s`` in the metadata
lists the releases in the file's time frame, so ``store.csv_import`` cuts the runs
exactly where the recording's release events put them. Writers are picked by
format name from ``WRITERS``, the way python-can picks log writers by suffix.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadRecordingInput, InputError
from ..samples import AXIS_FIELDS, SAMPLE_UNITS
from .csv_import import EXPORT_MARK as CSV_MARK
from .reader import _finite_increasing, _release_times, read_recording, truncation_notice
from .schemas import TOPIC_SAMPLES

FRAMES = ("device", "release")
#: Column suffix of each SI unit: the suffix ``csv_import`` reads the unit from.
UNIT_SUFFIX = {"s": "s", "rad": "rad", "rad/s": "rad_s", "m/s^2": "m_s2"}


@dataclass
class ExportTable:
    """Columns (name -> values, names carry the unit suffix), their units, and the run metadata."""

    name: str
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    metadata: dict[str, object]


def recording_table(path: str | Path, frame: str = "device") -> ExportTable:
    """The export table of one recording; ``frame='release'`` puts t = 0 at the first release."""
    if frame not in FRAMES:
        raise InputError(f"frame {frame!r} not understood: use {' or '.join(FRAMES)}")
    recording = read_recording(path)
    axis = recording.axis
    angle_field, rate_field = AXIS_FIELDS[axis]
    samples = recording.samples
    samples = samples[_finite_increasing(samples["t"], samples[angle_field], samples[rate_field])]
    if samples.size == 0:
        raise BadRecordingInput(
            f"{recording.path}: no sample with a finite time, {axis} angle and rate: nothing to export "
            f"(a tankdaq recording holds them on {TOPIC_SAMPLES})"
        )
    releases = _release_times(recording.events)
    origin = releases[0] if frame == "release" and releases else 0.0
    columns = {
        "time_s": samples["t"] - origin,
        "angle_rad": samples[angle_field],
        "rate_rad_s": samples[rate_field],
    }
    units = {"time_s": "s", "angle_rad": "rad", "rate_rad_s": "rad/s"}
    for field in samples.dtype.names:
        if field in ("t", angle_field, rate_field):
            continue
        unit = SAMPLE_UNITS[field]
        name = f"{field}_{UNIT_SUFFIX[unit]}" if unit in UNIT_SUFFIX else field
        columns[name] = samples[field].astype(float)
        units[name] = unit
    metadata: dict[str, object] = {
        **recording.metadata,
        "source": str(recording.path),
        "axis": axis,
        "frame": frame,
        "time_origin_s": origin,
        "release_t_s": [r - origin for r in releases],
        "dropped_rows": int(recording.samples.size - samples.size),
        "complete_file": recording.complete,
    }
    return ExportTable(recording.path.stem, columns, units, metadata)


def write_csv(table: ExportTable, path: Path) -> Path:
    """Comment block (metadata, one JSON value per key), header, units row, rows at full precision."""
    lines = [f"{CSV_MARK} of {table.metadata.get('source', table.name)}"]
    lines += [f"# {key} = {json.dumps(value)}" for key, value in table.metadata.items()]
    lines.append(",".join(table.columns))
    lines.append(",".join(table.units[name] for name in table.columns))
    matrix = np.column_stack(list(table.columns.values()))
    lines += [",".join(repr(float(x)) for x in row) for row in matrix]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_mat(table: ExportTable, path: Path) -> Path:
    """One struct ``tankdaq`` with the columns, ``units`` and ``meta`` (scipy.io.savemat, MATLAB 5)."""
    from scipy.io import savemat

    meta = {key: json.dumps(value) if isinstance(value, list | dict | bool) else value for key, value in
            table.metadata.items() if value is not None}  # fmt: skip
    struct = {**table.columns, "units": dict(table.units), "meta": meta}
    savemat(path, {"tankdaq": struct}, long_field_names=True, oned_as="column")
    return path


#: Writer by format name; the format name is also the file suffix.
WRITERS: dict[str, Callable[[ExportTable, Path], Path]] = {"csv": write_csv, "mat": write_mat}


def export_recording(
    path: str | Path,
    file_format: str,
    out_dir: Path | None = None,
    frame: str = "device",
    on_notice: Callable[[str], None] | None = None,
) -> Path:
    """Write one recording as ``<out_dir>/<stem>.<format>`` (default beside it); returns the path written.

    ``on_notice`` hears the one line that says the recording is cut short, when it is.
    """
    writer = WRITERS.get(file_format)
    if writer is None:
        raise InputError(f"format {file_format!r} not understood: use {' or '.join(WRITERS)}")
    table = recording_table(path, frame)
    if not table.metadata["complete_file"] and on_notice is not None:
        on_notice(truncation_notice(path))
    folder = out_dir if out_dir is not None else Path(path).parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return writer(table, folder / f"{table.name}.{file_format}")
    except OSError as exc:
        raise InputError(f"cannot write into {folder}: {exc.strerror or exc}") from None
