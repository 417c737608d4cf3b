"""Records of named float columns on disk, as MCAP or CSV: the encoding under ``auv.io``'s
diving-plane records, kept here so that only the store speaks MCAP.

MCAP layout: one channel of JSON messages (schema encoding "jsonschema", message encoding "json"), one
message per sample holding every column, stamped by the first column (time in s); channel metadata gives
each column's unit; one metadata record of strings says what the record is; at most one file rides along
as an attachment. CSV layout: ``# key: value`` comment lines for the same metadata, then a header of
unit-suffixed names (``q_rad_s``), then one row per sample. The caller owns the meaning of the columns.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
from mcap.reader import make_reader
from mcap.writer import Writer

from .._version import __version__
from ..errors import BadRecordingInput
from .record_scan import MCAP_DAMAGE
from .safe_write import write_new, write_text_new

#: Columns read back, by field name, in file order.
Columns = dict[str, list[float]]


@dataclass(frozen=True)
class ColumnLayout:
    """Where a kind of column record keeps its samples and metadata, and what its columns are."""

    topic: str
    schema_name: str
    #: The JSON schema's description of one sample.
    description: str
    metadata_name: str
    #: Field -> unit, in column order; the first field is the time in s.
    units: Mapping[str, str]
    #: What an error calls a file of this kind, e.g. "tankdaq auv record".
    what: str

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(self.units)

    @property
    def csv_names(self) -> dict[str, str]:
        """CSV header names: the field with its unit, e.g. ``q_rad_s``."""
        return {f: f"{f}_{unit.replace('/', '_')}" for f, unit in self.units.items()}

    def schema(self) -> dict[str, object]:
        return {
            "title": self.schema_name,
            "description": self.description,
            "type": "object",
            "properties": {f: {"type": "number", "description": f"unit: {u}"} for f, u in self.units.items()},
            "required": list(self.fields),
        }


@dataclass(frozen=True)
class FileAttachment:
    """A file stored inside an MCAP record (e.g. the vehicle description it was simulated with)."""

    name: str
    media_type: str
    data: bytes


def _rows(layout: ColumnLayout, columns: Mapping[str, np.ndarray]) -> np.ndarray:
    return np.column_stack([columns[f] for f in layout.fields])


def write_csv(
    path: Path, layout: ColumnLayout, columns: Mapping[str, np.ndarray], meta: Mapping[str, str]
) -> None:
    """The columns as a new CSV file under ``# key: value`` metadata lines (CSV carries no attachment)."""
    text = io.StringIO(newline="")
    for key, value in meta.items():
        text.write(f"# {key}: {value}\n")
    writer = csv.writer(text)
    writer.writerow([layout.csv_names[f] for f in layout.fields])
    writer.writerows(_rows(layout, columns).tolist())
    write_text_new(path, text.getvalue())


def write_mcap(
    path: Path,
    layout: ColumnLayout,
    columns: Mapping[str, np.ndarray],
    meta: Mapping[str, str],
    attachment: FileAttachment | None = None,
) -> None:
    """The columns as a new MCAP file: one channel, one message per sample, the metadata and attachment."""
    write_new(path, lambda fh: _write_mcap(fh, layout, columns, meta, attachment))


def _write_mcap(
    fh: BinaryIO,
    layout: ColumnLayout,
    columns: Mapping[str, np.ndarray],
    meta: Mapping[str, str],
    attachment: FileAttachment | None,
) -> None:
    writer = Writer(fh)
    writer.start(profile="", library=f"tankdaq {__version__}")
    schema_id = writer.register_schema(layout.schema_name, "jsonschema", json.dumps(layout.schema()).encode())
    channel_id = writer.register_channel(layout.topic, "json", schema_id, metadata=dict(layout.units))
    for sequence, row in enumerate(_rows(layout, columns)):
        stamp = round(row[0] * 1e9)
        data = json.dumps(dict(zip(layout.fields, row.tolist(), strict=True))).encode()
        writer.add_message(channel_id, log_time=stamp, data=data, publish_time=stamp, sequence=sequence)
    writer.add_metadata(layout.metadata_name, {k: str(v) for k, v in meta.items()})
    if attachment is not None:
        writer.add_attachment(
            create_time=0,
            log_time=0,
            name=attachment.name,
            media_type=attachment.media_type,
            data=attachment.data,
        )
    writer.finish()


def read_csv(path: Path, layout: ColumnLayout) -> tuple[Columns, dict[str, str]]:
    """The columns (by field, also under their unit-suffixed names) and ``# key: value`` metadata of a CSV
    record; unknown columns come back under their own header name."""
    meta: dict[str, str] = {}
    by_header = {name: field for field, name in layout.csv_names.items()} | {f: f for f in layout.fields}
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
    except (csv.Error, UnicodeDecodeError) as exc:
        raise BadRecordingInput(f"{path}: not a readable CSV record ({exc})") from None
    if not rows:
        raise BadRecordingInput(f"{path}: no header row and no samples")
    header = [by_header.get(h.strip(), h.strip()) for h in rows[0]]
    columns: Columns = {h: [] for h in header}
    for number, row in enumerate(rows[1:], start=1):
        if len(row) != len(header):
            raise BadRecordingInput(
                f"{path}: sample row {number} has {len(row)} fields, the header {len(header)}"
            )
        for h, value in zip(header, row, strict=True):
            try:
                columns[h].append(float(value))
            except ValueError:
                raise BadRecordingInput(
                    f"{path}: sample row {number}, column {h!r}: {value.strip()[:30]!r} is not a number"
                ) from None
    return columns, meta


def read_mcap(path: Path, layout: ColumnLayout) -> tuple[Columns, dict[str, str]]:
    """The columns and metadata of an MCAP record; a sample without a field just lacks it."""
    columns: Columns = {f: [] for f in layout.fields}
    meta: dict[str, str] = {}
    try:
        with path.open("rb") as fh:
            reader = make_reader(fh)
            for item in reader.iter_metadata():
                if item.name == layout.metadata_name:
                    meta.update(item.metadata)
            for _, _, message in reader.iter_messages(topics=[layout.topic]):
                sample = json.loads(message.data)
                for f in layout.fields:
                    if f in sample:
                        columns[f].append(sample[f])
    except (*MCAP_DAMAGE, KeyError, EOFError, OSError) as exc:
        raise BadRecordingInput(f"{path}: not a readable MCAP record ({exc})") from None
    if not columns[layout.fields[0]]:
        raise BadRecordingInput(f"{path}: no messages on {layout.topic}; is this a {layout.what}?")
    return columns, meta


def read_attachments(path: Path) -> list[FileAttachment]:
    """The files an MCAP record carries, in file order."""
    try:
        with path.open("rb") as fh:
            return [FileAttachment(a.name, a.media_type, a.data) for a in make_reader(fh).iter_attachments()]
    except (*MCAP_DAMAGE, EOFError, OSError) as exc:
        raise BadRecordingInput(f"{path}: its attachments cannot be read ({exc})") from None
