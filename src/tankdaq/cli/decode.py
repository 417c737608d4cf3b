"""``tankdaq decode``: a raw Xsens capture (serial bytes) to JSON lines or CSV, in device units."""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import fields, is_dataclass
from enum import StrEnum
from pathlib import Path
from typing import IO, Annotated

import numpy as np
import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from ..errors import InputError
from ..xsens.batch import DecodedBlock
from ..xsens.mtdata2 import SPEC_BY_NAME, UtcTime, to_jsonable
from ..xsens.stream import StreamDecoder
from ..xsens.timebase import CounterTracker
from .app import app, err_console, handles_errors

CHUNK_BYTES = 1 << 20
WRITE_BATCH = 10_000

#: Component labels of vector outputs in CSV headers (x, y, z for the rest).
COMPONENTS: dict[str, tuple[str, ...]] = {
    "EulerAngles": ("roll", "pitch", "yaw"),
    "Quaternion": ("q0", "q1", "q2", "q3"),
    "DeltaQ": ("q0", "q1", "q2", "q3"),
    "RotationMatrix": tuple("abcdefghi"),
    "LatLon": ("lat", "lon"),
    "RawAccGyrMagTemp": (
        "acc_x",
        "acc_y",
        "acc_z",
        "gyr_x",
        "gyr_y",
        "gyr_z",
        "mag_x",
        "mag_y",
        "mag_z",
        "temp",
    ),
}
#: Unit suffixes of CSV columns, from the data-identifier table's units.
UNIT_SUFFIXES = {
    "deg": "_deg", "rad/s": "_rad_s", "m/s^2": "_m_s2", "m/s": "_m_s", "m": "_m", "degC": "_degC",
    "Pa": "_Pa", "0.1 ms": "_ticks", "s": "_s",
}  # fmt: skip


class OutputFormat(StrEnum):
    """What ``decode`` writes."""

    jsonl = "jsonl"
    csv = "csv"


def read_capture(path: Path) -> bytes:
    """The capture's bytes; a one-line InputError when it cannot be used."""
    if not path.exists():
        raise InputError(f"capture {path} does not exist")
    if path.is_dir():
        raise InputError(f"capture {path} is a directory; give the raw capture file (e.g. output.bin)")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read capture {path}: {exc.strerror}") from None
    if not data:
        raise InputError(f"capture {path} is empty")
    return data


def flatten(name: str, value: object) -> dict[str, object]:
    """CSV columns of one output value: vectors and structured outputs become one column per part."""
    suffix = UNIT_SUFFIXES.get(SPEC_BY_NAME[name].unit, "") if name in SPEC_BY_NAME else ""
    if isinstance(value, UtcTime):
        return {name: value.isoformat(), f"{name}.flags": value.flags}
    if is_dataclass(value):
        return {
            f"{name}.{f.name}": json.dumps(to_jsonable(getattr(value, f.name)), separators=(",", ":"))
            if isinstance(getattr(value, f.name), tuple)
            else getattr(value, f.name)
            for f in fields(value)
        }
    if isinstance(value, tuple):
        labels = COMPONENTS.get(name, ("x", "y", "z"))
        return {f"{name}.{label}{suffix}": part for label, part in zip(labels, value, strict=True)}
    return {f"{name}{suffix}": value}


@contextmanager
def open_output(out: Path | None) -> Iterator[IO[str]]:
    """The output file (or stdout), with a one-line error when it cannot be written."""
    if out is None:
        yield sys.stdout
        return
    try:
        handle = out.open("w", newline="")
    except OSError as exc:
        raise InputError(f"cannot write {out}: {exc.strerror}") from None
    with handle:
        yield handle


def progress() -> Progress:
    """A transient progress display on stderr (stdout stays machine-readable)."""
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    return Progress(*columns, console=err_console, transient=True)


def decode_all(data: bytes, bar: Progress, label: str) -> DecodedBlock:
    """Stream-decode ``data`` in 1 MiB pieces (progress in KiB)."""
    decoder = StreamDecoder()
    task = bar.add_task(f"decoding {label} (KiB)", total=len(data) // 1024 + 1)
    blocks = []
    for start in range(0, len(data), CHUNK_BYTES):
        blocks.append(decoder.feed(data[start : start + CHUNK_BYTES]))
        bar.advance(task, CHUNK_BYTES // 1024)
    return DecodedBlock.concat(blocks)


def csv_header(block: DecodedBlock) -> list[str]:
    """Every column a row can have: each output's flattened parts, in order of first appearance."""
    header: list[str] = []
    for name in block.columns:
        first = int(np.argmax(block.present[name]))
        header += flatten(name, block.message(first)[name])
    return header


def write_messages(block: DecodedBlock, handle: IO[str], output_format: OutputFormat, bar: Progress) -> None:
    """One JSON object or CSV row per message, in batches (columns go to Python once per batch)."""
    task = bar.add_task("writing messages", total=block.n_messages)
    writer = None
    if output_format is OutputFormat.csv:
        writer = csv.DictWriter(handle, fieldnames=csv_header(block), restval="", lineterminator="\n")
        writer.writeheader()
    for start in range(0, block.n_messages, WRITE_BATCH):
        for message in block.messages(start, start + WRITE_BATCH):
            if writer is None:
                values = {name: to_jsonable(value) for name, value in message.items()}
                handle.write(json.dumps(values, separators=(",", ":")) + "\n")
            else:
                writer.writerow(
                    {
                        col: cell
                        for name, value in message.items()
                        for col, cell in flatten(name, value).items()
                    }
                )
        bar.advance(task, min(WRITE_BATCH, block.n_messages - start))


def summary_line(block: DecodedBlock, tracker: CounterTracker) -> str:
    """What was in the capture, for stderr."""
    parts = [
        f"{block.n_messages} MTData2 messages",
        f"{len(block.other_frames)} other frames",
        f"{block.bad_checksums} bad checksums",
        f"{block.skipped_bytes} skipped bytes",
        f"{block.unknown_ids} unknown identifiers",
        f"{tracker.gap_count} counter gaps ({tracker.lost} packets lost)",
    ]
    if block.malformed:
        parts.append(f"{block.malformed} malformed messages")
    if block.pending_bytes:
        parts.append(f"{block.pending_bytes} bytes of a truncated last frame")
    return ", ".join(parts)


@app.command("decode")
@handles_errors
def decode_command(
    capture: Annotated[Path, typer.Argument(help="Raw capture: the bytes as read from the serial port.")],
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="jsonl or csv.")
    ] = OutputFormat.jsonl,
    out: Annotated[Path | None, typer.Option("--out", help="Write here instead of stdout.")] = None,
) -> None:
    """Decode a raw Xsens capture: one JSON object (or CSV row) per MTData2 message, device units."""
    data = read_capture(capture)
    with progress() as bar:
        block = decode_all(data, bar, capture.name)
        if block.frames == 0:
            raise InputError(f"no Xbus frames in {capture} ({len(data)} bytes): is it a raw serial capture?")
        with open_output(out) as handle:
            write_messages(block, handle, output_format, bar)
    tracker = CounterTracker()
    if "PacketCounter" in block.columns:
        tracker.update_many(block.columns["PacketCounter"][block.present["PacketCounter"]])
    err_console.print(
        f"{capture.name}: {summary_line(block, tracker)}", markup=False, highlight=False, soft_wrap=True
    )
