"""Diving-plane records on disk: MCAP (as the recorder writes) or CSV, the reader and writer picked by the
suffix (``store.inputs.by_suffix`` over this module's tables); ``store.column_records`` does the encoding.

MCAP layout: one channel ``/auv/state`` of JSON messages (schema encoding "jsonschema", message encoding
"json"), one message per sample with t, u, w, q, theta, z, x, delta_s in SI units and rad; channel
metadata gives each field's unit; a metadata record ``tankdaq.auv`` says what the record is (vehicle,
manoeuvre, angles, noise, software version; all strings); the vehicle file rides along as an attachment.
CSV layout: ``# key: value`` comment lines for the same metadata, then a header of unit-suffixed names.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np

from .._version import __version__
from ..config.validation import input_file
from ..errors import BadRecordingInput, InputError
from ..store import column_records
from ..store.column_records import ColumnLayout, FileAttachment
from ..store.inputs import by_suffix
from .model import STATE_COLUMNS, STATE_UNITS, StateRecord
from .vehicle import Vehicle, vehicle_from_dict

TOPIC = "/auv/state"
METADATA_NAME = "tankdaq.auv"
FIELDS: tuple[str, ...] = ("t", *STATE_COLUMNS)
#: What the suffix errors call these files.
WHAT = "diving-plane records"

LAYOUT = ColumnLayout(
    topic=TOPIC,
    schema_name="tankdaq.auv.State",
    description="Diving-plane state of an AUV, body axes (x forward, z down), pitch nose-up positive",
    metadata_name=METADATA_NAME,
    units={f: STATE_UNITS[f] for f in FIELDS},
    what="tankdaq auv record",
)


def write_record(path: str | Path, record: StateRecord, vehicle: Vehicle | None = None) -> Path:
    """Write a record as MCAP or CSV according to the suffix; returns the path."""
    path = Path(path)
    write = by_suffix(path, _WRITERS, WHAT)
    meta = {**record.meta, "software": f"tankdaq {__version__}"}
    if not path.parent.is_dir():
        raise InputError(f"{path}: the folder {path.parent} does not exist")
    write(path, record, meta, vehicle)
    return path


def _columns(record: StateRecord) -> dict[str, np.ndarray]:
    return {"t": record.t} | {c: record[c] for c in STATE_COLUMNS}


def _write_csv(path: Path, record: StateRecord, meta: dict[str, str], _vehicle: Vehicle | None) -> None:
    """CSV carries no attachment: the vehicle stays with the caller."""
    column_records.write_csv(path, LAYOUT, _columns(record), meta)


def _vehicle_attachment(vehicle: Vehicle) -> FileAttachment:
    if vehicle.path is not None:
        return FileAttachment(f"{vehicle.name}.toml", "application/toml", vehicle.path.read_bytes())
    blob = json.dumps(vehicle.to_dict(), indent=1).encode()
    return FileAttachment(f"{vehicle.name}.json", "application/json", blob)


def _write_mcap(path: Path, record: StateRecord, meta: dict[str, str], vehicle: Vehicle | None) -> None:
    attachment = _vehicle_attachment(vehicle) if vehicle is not None else None
    column_records.write_mcap(path, LAYOUT, _columns(record), meta, attachment)


def read_record(path: str | Path) -> StateRecord:
    """Read a record written by ``write_record`` (or any file with the same layout)."""
    path = Path(path)
    if path.is_dir():  # said to be a folder, not a file of an unknown type
        input_file(path, error=BadRecordingInput)
    read = by_suffix(path, _READERS, WHAT)
    input_file(path, error=BadRecordingInput)
    return read(path)


def _columns_to_record(path: Path, columns: dict[str, list[float]], meta: dict[str, str]) -> StateRecord:
    missing = [f for f in FIELDS if f not in columns or not columns[f]]
    if missing:
        raise BadRecordingInput(
            f"{path}: missing channels {missing}; a diving-plane record needs {', '.join(FIELDS)}"
        )
    arrays = {f: np.asarray(columns[f], dtype=float) for f in FIELDS}
    return StateRecord(t=arrays["t"], states={c: arrays[c] for c in STATE_COLUMNS}, meta=meta)


def _read_csv(path: Path) -> StateRecord:
    return _columns_to_record(path, *column_records.read_csv(path, LAYOUT))


def _read_mcap(path: Path) -> StateRecord:
    return _columns_to_record(path, *column_records.read_mcap(path, LAYOUT))


def read_vehicle_attachment(path: str | Path) -> Vehicle | None:
    """The vehicle an MCAP record carries as an attachment (None for CSV or when absent)."""
    path = Path(path)
    if by_suffix(path, _READERS, WHAT) is not _read_mcap:
        return None
    for attachment in column_records.read_attachments(path):
        try:
            if attachment.media_type == "application/toml":
                return vehicle_from_dict(tomllib.loads(attachment.data.decode()))
            if attachment.media_type == "application/json":
                return vehicle_from_dict(json.loads(attachment.data))
        except (ValueError, tomllib.TOMLDecodeError) as exc:
            raise BadRecordingInput(f"{path}: the vehicle attachment cannot be read ({exc})") from None
    return None


#: Suffix -> writer and reader (one table each, as ``store.inputs.INPUT_FORMATS`` for decays).
_WRITERS = {".mcap": _write_mcap, ".csv": _write_csv}
_READERS = {".mcap": _read_mcap, ".csv": _read_csv}
