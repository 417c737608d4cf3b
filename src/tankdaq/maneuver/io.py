"""Diving-plane records on disk: MCAP (as the recorder writes) or CSV, the reader and writer picked by the
suffix (``store.inputs.by_suffix`` over this module's tables).

MCAP layout: one channel ``/auv/state`` of JSON messages (schema encoding "jsonschema", message encoding
"json"), one message per sample with t, u, w, q, theta, z, x, delta_s in SI units and rad; channel
metadata gives each field's unit; a metadata record ``tankdaq.auv`` says what the record is (vehicle,
manoeuvre, angles, noise, software version; all strings); the vehicle file rides along as an attachment.
CSV layout: ``# key: value`` comment lines for the same metadata, then a header of unit-suffixed names.
"""

from __future__ import annotations

import csv
import json
import tomllib
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import Writer

from .. import __version__
from ..errors import BadRecordingInput, InputError
from ..store.inputs import by_suffix
from ..validation import input_file
from .model import STATE_COLUMNS, STATE_UNITS, StateRecord
from .vehicle import Vehicle, vehicle_from_dict

TOPIC = "/auv/state"
METADATA_NAME = "tankdaq.auv"
SCHEMA_NAME = "tankdaq.auv.State"
FIELDS: tuple[str, ...] = ("t", *STATE_COLUMNS)
#: CSV header names: the field with its unit, e.g. ``q_rad_s``.
CSV_NAMES: dict[str, str] = {f: f"{f}_{STATE_UNITS[f].replace('/', '_')}" for f in FIELDS}
#: What the suffix errors call these files.
WHAT = "diving-plane records"

_SCHEMA = {
    "title": SCHEMA_NAME,
    "description": "Diving-plane state of an AUV, body axes (x forward, z down), pitch nose-up positive",
    "type": "object",
    "properties": {f: {"type": "number", "description": f"unit: {STATE_UNITS[f]}"} for f in FIELDS},
    "required": list(FIELDS),
}


def write_record(path: str | Path, record: StateRecord, vehicle: Vehicle | None = None) -> Path:
    """Write a record as MCAP or CSV according to the suffix; returns the path."""
    path = Path(path)
    write = by_suffix(path, _WRITERS, WHAT)
    meta = {**record.meta, "software": f"tankdaq {__version__}"}
    if not path.parent.is_dir():
        raise InputError(f"{path}: the folder {path.parent} does not exist")
    write(path, record, meta, vehicle)
    return path


def _write_csv(path: Path, record: StateRecord, meta: dict[str, str], _vehicle: Vehicle | None) -> None:
    """CSV carries no attachment: the vehicle stays with the caller."""
    with path.open("w", newline="") as fh:
        for key, value in meta.items():
            fh.write(f"# {key}: {value}\n")
        writer = csv.writer(fh)
        writer.writerow([CSV_NAMES[f] for f in FIELDS])
        columns = [record.t] + [record[c] for c in STATE_COLUMNS]
        writer.writerows(np.column_stack(columns).tolist())


def _vehicle_attachment(vehicle: Vehicle) -> tuple[str, str, bytes]:
    if vehicle.path is not None:
        return f"{vehicle.name}.toml", "application/toml", vehicle.path.read_bytes()
    return f"{vehicle.name}.json", "application/json", json.dumps(vehicle.to_dict(), indent=1).encode()


def _write_mcap(path: Path, record: StateRecord, meta: dict[str, str], vehicle: Vehicle | None) -> None:
    with path.open("wb") as fh:
        writer = Writer(fh)
        writer.start(profile="", library=f"tankdaq {__version__}")
        schema_id = writer.register_schema(SCHEMA_NAME, "jsonschema", json.dumps(_SCHEMA).encode())
        units = {f: STATE_UNITS[f] for f in FIELDS}
        channel_id = writer.register_channel(TOPIC, "json", schema_id, metadata=units)
        columns = np.column_stack([record.t] + [record[c] for c in STATE_COLUMNS])
        for sequence, row in enumerate(columns):
            stamp = round(row[0] * 1e9)
            data = json.dumps(dict(zip(FIELDS, row.tolist(), strict=True))).encode()
            writer.add_message(channel_id, log_time=stamp, data=data, publish_time=stamp, sequence=sequence)
        writer.add_metadata(METADATA_NAME, {k: str(v) for k, v in meta.items()})
        if vehicle is not None:
            name, media_type, blob = _vehicle_attachment(vehicle)
            writer.add_attachment(create_time=0, log_time=0, name=name, media_type=media_type, data=blob)
        writer.finish()


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
            f"{path}: missing channels {missing}; a diving-plane record needs {', '.join(FIELDS)}")
    arrays = {f: np.asarray(columns[f], dtype=float) for f in FIELDS}
    return StateRecord(t=arrays["t"], states={c: arrays[c] for c in STATE_COLUMNS}, meta=meta)


def _read_csv(path: Path) -> StateRecord:
    meta: dict[str, str] = {}
    by_header = {name: field for field, name in CSV_NAMES.items()} | {f: f for f in FIELDS}
    try:
        with path.open(newline="") as fh:
            lines = [line for line in fh if line.strip()]
        body = []
        for line in lines:
            if line.startswith("#"):
                key, _, value = line[1:].partition(":")
                meta[key.strip()] = value.strip()
            else:
                body.append(line)
        rows = list(csv.reader(body))
        if not rows:
            raise BadRecordingInput(f"{path}: no header row and no samples")
        header = [by_header.get(h.strip(), h.strip()) for h in rows[0]]
        columns: dict[str, list[float]] = {h: [] for h in header}
        for row in rows[1:]:
            for h, value in zip(header, row, strict=True):
                columns[h].append(float(value))
    except (ValueError, UnicodeDecodeError) as exc:
        raise BadRecordingInput(f"{path}: not a readable CSV record ({exc})") from None
    return _columns_to_record(path, columns, meta)


def _read_mcap(path: Path) -> StateRecord:
    columns: dict[str, list[float]] = {f: [] for f in FIELDS}
    meta: dict[str, str] = {}
    try:
        with path.open("rb") as fh:
            reader = make_reader(fh)
            for item in reader.iter_metadata():
                if item.name == METADATA_NAME:
                    meta.update(item.metadata)
            for _, _, message in reader.iter_messages(topics=[TOPIC]):
                sample = json.loads(message.data)
                for f in FIELDS:
                    if f in sample:
                        columns[f].append(sample[f])
    except (McapError, ValueError, KeyError, EOFError, OSError) as exc:
        raise BadRecordingInput(f"{path}: not a readable MCAP record ({exc})") from None
    if not columns["t"]:
        raise BadRecordingInput(f"{path}: no messages on {TOPIC}; is this a tankdaq auv record?")
    return _columns_to_record(path, columns, meta)


def read_vehicle_attachment(path: str | Path) -> Vehicle | None:
    """The vehicle an MCAP record carries as an attachment (None for CSV or when absent)."""
    path = Path(path)
    if by_suffix(path, _READERS, WHAT) is not _read_mcap:
        return None
    try:
        with path.open("rb") as fh:
            for attachment in make_reader(fh).iter_attachments():
                if attachment.media_type == "application/toml":
                    return vehicle_from_dict(tomllib.loads(attachment.data.decode()))
                if attachment.media_type == "application/json":
                    return vehicle_from_dict(json.loads(attachment.data))
    except (McapError, ValueError, tomllib.TOMLDecodeError, OSError) as exc:
        raise BadRecordingInput(f"{path}: the vehicle attachment cannot be read ({exc})") from None
    return None


#: Suffix -> writer and reader (one table each, as ``store.inputs.INPUT_FORMATS`` for decays).
_WRITERS = {".mcap": _write_mcap, ".csv": _write_csv}
_READERS = {".mcap": _read_mcap, ".csv": _read_csv}
