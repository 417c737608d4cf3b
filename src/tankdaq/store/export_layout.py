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
