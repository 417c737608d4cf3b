"""The names an exported recording's files use, shared by ``store.export`` (writing) and
``store.csv_import`` (reading an exported CSV back).

Columns are the sample fields of ``samples.SAMPLE_DTYPE`` with their SI unit as a suffix (``roll_rad``,
``p_rad_s``, ``az_m_s2``): the MCAP archive's values unchanged, so a file holds the recording to the last
bit, and one name whatever the tool (pandas, Excel, MATLAB, h5py). The run metadata travels beside a CSV
as ``<stem>.json`` (also the campaign's label sidecar: hull, draft, axis, angle_deg), inside HDF5 as
root attributes and inside Parquet as schema metadata, always marked ``"format": EXPORT_FORMAT``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..samples import AXIS_FIELDS, SAMPLE_UNITS

#: ``format`` in an export's metadata: how a reader tells a tankdaq export's sidecar from any JSON.
EXPORT_FORMAT = "tankdaq export"
#: Time column: time since the release (``--frame release``) or the device clock (``--frame device``).
TIME_COLUMN = "time_s"
#: The device clock beside time since release, so the recording's own times stay in the file exactly.
DEVICE_TIME_COLUMN = "device_time_s"
#: Column suffix of each SI unit: the suffix ``csv_import`` reads the unit from.
UNIT_SUFFIX = {"s": "s", "rad": "rad", "rad/s": "rad_s", "m/s^2": "m_s2"}


def column_name(field: str) -> str:
    """The export column of a sample field: the field and its unit's suffix (``p`` -> ``p_rad_s``)."""
    unit = SAMPLE_UNITS[field]
    return f"{field}_{UNIT_SUFFIX[unit]}" if unit in UNIT_SUFFIX else field


def axis_columns(axis: str) -> tuple[str, str]:
    """The angle and rate columns of a decay axis (``roll`` -> ``roll_rad``, ``p_rad_s``)."""
    angle, rate = AXIS_FIELDS[axis]
    return column_name(angle), column_name(rate)


def sidecar_path(path: Path) -> Path:
    """Where an exported CSV's metadata is: ``<stem>.json`` beside it."""
    return path.with_suffix(".json")


def read_sidecar(path: Path) -> dict[str, object] | None:
    """The metadata of an exported CSV from its sidecar; None when there is none or it is not a tankdaq
    export's (a campaign label sidecar, another tool's JSON): then the CSV is read as any other."""
    sidecar = sidecar_path(path)
    try:
        data = json.loads(sidecar.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(data, dict) or data.get("format") != EXPORT_FORMAT:
        return None
    return data


@dataclass
class ExportTable:
    """Columns (name -> values, names carry the unit suffix), their units, and the run metadata."""

    name: str
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    metadata: dict[str, object]


def read_h5_metadata(path: Path) -> dict[str, object] | None:
    """The metadata of an HDF5 file ``tankdaq export`` wrote (its root attributes); None for another
    tool's HDF5 file. A file HDF5 cannot open raises ``OSError``."""
    import h5py

    with h5py.File(path, "r") as h5:
        found = {key: h5.attrs[key] for key in h5.attrs}
    return found if found.get("format") == EXPORT_FORMAT else None


def read_parquet_metadata(path: Path) -> dict[str, object] | None:
    """The metadata of a Parquet file ``tankdaq export`` wrote (the JSON under its schema metadata key
    ``tankdaq``, read from the footer alone); None for another tool's Parquet file. Needs pyarrow
    (``ImportError`` without it); a file pyarrow cannot read raises ``OSError`` or ``ValueError``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        text = (pq.read_schema(path).metadata or {}).get(b"tankdaq")
    except pa.ArrowException as exc:  # not a Parquet file, or one of a kind pyarrow does not read
        raise ValueError(str(exc)) from None
    try:
        found = json.loads(text) if text is not None else None
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    return found if isinstance(found, dict) and found.get("format") == EXPORT_FORMAT else None


def read_mat_metadata(path: Path) -> dict[str, object] | None:
    """The metadata of a MATLAB file ``tankdaq export`` wrote (its struct ``tankdaq``'s ``meta``, lists
    and booleans as the JSON text they were written as); None for another tool's .mat file. A file
    scipy cannot read raises ``ValueError`` or ``OSError``."""
    from scipy.io import loadmat, whosmat

    try:
        if not any(name == "tankdaq" for name, _shape, kind in whosmat(path) if kind == "struct"):
            return None  # whosmat reads the variables' headers only: another tool's file is not loaded
        struct = loadmat(path, variable_names=["tankdaq"], simplify_cells=True)["tankdaq"]
    except OSError:
        raise
    except Exception as exc:  # scipy fails in many ways on bytes that are no MATLAB file (IndexError...)
        raise ValueError(f"{type(exc).__name__}: {exc}") from None
    meta = struct.get("meta") if isinstance(struct, dict) else None
    if not isinstance(meta, dict) or meta.get("format") != EXPORT_FORMAT:
        return None
    return {str(key): value.item() if isinstance(value, np.generic) else value for key, value in meta.items()}


def exports_among(paths: Sequence[Path]) -> dict[Path, Path]:
    """The CSV exports among ``paths`` whose own recording is among them too (export -> recording). Read
    both, each decay would count twice: as a repeat, narrowing every interval. An export names its
    recording in its sidecar (``source``, as given to ``tankdaq export``): found at that path, or by
    that name in the export's own folder (the default, ``export`` writes beside each recording)."""
    recordings = {path.resolve(): path for path in paths if path.suffix.lower() == ".mcap"}
    found: dict[Path, Path] = {}
    for path in paths:
        meta = read_sidecar(path) if path.suffix.lower() == ".csv" else None
        source = meta.get("source") if meta is not None else None
        if not isinstance(source, str) or not source:
            continue
        for candidate in (Path(source), path.parent / Path(source).name):
            recording = recordings.get(candidate.resolve())
            if recording is not None:
                found[path] = recording
                break
    return found
