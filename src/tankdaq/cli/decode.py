"""``tankdaq decode``: a raw Xsens capture (serial bytes) to JSON lines or CSV, in device units."""

from __future__ import annotations

import csv
import heapq
import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import fields, is_dataclass
from enum import StrEnum
from operator import itemgetter
from pathlib import Path
from typing import IO, TYPE_CHECKING, Annotated, cast

import numpy as np
import typer

from ..config.validation import input_file, new_file
from ..errors import InputError, ProtocolError
from ..xsens.constants import MID
from .app import TerminalProgress, app, checked, err_console, handles_errors

if TYPE_CHECKING:  # the decoders (and mcap) are imported by the command itself: --help stays quick
    from ..api.progress import Progress
    from ..xsens.column_decoder import DecodedBlock
    from ..xsens.mtdata2 import MTData2Message
    from ..xsens.timebase import CounterTracker

CHUNK_BYTES = 1 << 20
#: The column (JSON key) of a log's rows that says which device sent it, when the log holds several.
BUS_ID = "BusId"
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
    from ..store.record_scan import is_mcap

    input_file(path, "raw capture file (e.g. output.bin)")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read capture {path}: {exc.strerror}") from None
    if not data:
        raise InputError(f"capture {path} is empty")
    if is_mcap(data):  # its bytes would only be counted as hundreds of bad checksums
        raise InputError(
            f"{path} is an MCAP recording, not a raw capture; its serial bytes are replayed by "
            f"tankdaq replay {path} (read them with tankdaq.store.reader.iter_raw_chunks)"
        )
    return data


def flatten(name: str, value: object) -> dict[str, object]:
    """CSV columns of one output value: vectors and structured outputs become one column per part."""
    from ..xsens.mtdata2 import SPEC_BY_NAME, UtcTime, to_jsonable

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
    """The output file (or stdout): a new file, published whole when the decoding ends (``store.safe_write``),
    with a one-line error when it cannot be written."""
    if out is None:
        yield sys.stdout
        return
    from ..store.safe_write import new_path

    with new_path(out) as temporary, temporary.open("x", newline="") as handle:
        yield handle


def is_log(path: Path, data: bytes) -> bool:
    """An MT Manager log (``.mtb``, or bytes that start with the Configuration message a log starts with):
    its frames are read from every bus id (``xsens.mtb``), not only from the master's."""
    return path.suffix.lower() == ".mtb" or data[:3] == bytes((0xFA, 0xFF, MID.CONFIGURATION))


def decode_all(data: bytes, progress: Progress, label: str, log: bool = False) -> DecodedBlock:
    """Stream-decode ``data`` in 1 MiB pieces (progress in KiB); ``log``: as an MT Manager log."""
    from ..xsens.column_decoder import DecodedBlock
    from ..xsens.framer import ANY_BID
    from ..xsens.mtb import LOG_MAX_DATA_LENGTH
    from ..xsens.stream_decoder import StreamDecoder

    decoder = StreamDecoder(LOG_MAX_DATA_LENGTH, ANY_BID) if log else StreamDecoder()
    blocks = []
    with progress.task(f"decoding {label} (KiB)", total=len(data) // 1024 + 1) as update:
        for start in range(0, len(data), CHUNK_BYTES):
            blocks.append(decoder.feed(data[start : start + CHUNK_BYTES]))
            update(min(start + CHUNK_BYTES, len(data)) // 1024)
    return DecodedBlock.concat([*blocks, decoder.finish()])  # the capture ends: nothing follows it


def decode_legacy(block: DecodedBlock, mode: int, settings: int) -> list[tuple[int, MTData2Message]]:
    """(frame index, message) of every legacy MTData frame, decoded with the device's mode and settings."""
    from ..xsens.legacy import decode_mtdata

    decoded = []
    for index, frame in zip(block.other_index.tolist(), block.other_frames, strict=True):
        if frame.mid == MID.MTDATA:
            try:
                decoded.append((index, decode_mtdata(frame.payload, mode, settings)))
            except ProtocolError as exc:
                raise InputError(f"legacy frame {index}: {exc}") from None
    return decoded


def in_stream_order(
    block: DecodedBlock, legacy: list[tuple[int, MTData2Message]], by_device: bool = False
) -> Iterator[MTData2Message]:
    """MTData2 rows (converted in batches) and legacy messages, merged in the order they were sent
    (``by_device``: each MTData2 row says the bus id of the device that sent it, first, as ``BusId``)."""

    def mtdata2() -> Iterator[tuple[int, MTData2Message]]:
        for start in range(0, block.n_messages, WRITE_BATCH):
            indices = block.frame_index[start : start + WRITE_BATCH].tolist()
            messages = block.messages(start, start + WRITE_BATCH)
            if by_device:
                buses = block.bus_ids[start : start + WRITE_BATCH].tolist()
                messages = (_from(bus, message) for bus, message in zip(buses, messages, strict=True))
            yield from zip(indices, messages, strict=True)

    for _, message in heapq.merge(mtdata2(), legacy, key=itemgetter(0)):
        yield message


def _from(bus_id: int, message: MTData2Message) -> MTData2Message:
    """``message`` with the bus id of its device first."""
    from ..xsens.mtdata2 import MTData2Message

    return MTData2Message({BUS_ID: bus_id, **message}, message.xdis, message.unknown_xdis)


def csv_header(block: DecodedBlock, legacy: list[tuple[int, MTData2Message]]) -> list[str]:
    """Every column a row can have: each output's flattened parts, in order of first appearance."""
    header: list[str] = []
    for name in block.columns:
        first = int(np.argmax(block.present[name]))
        header += flatten(name, block.message(first)[name])
    if legacy:  # every legacy message has the same blocks
        header += [column for name, value in legacy[0][1].items() for column in flatten(name, value)]
    return list(dict.fromkeys(header))


def write_messages(
    messages: Iterator[MTData2Message],
    total: int,
    handle: IO[str],
    header: list[str] | None,
    progress: Progress,
) -> list[int]:
    """One JSON object (``header`` None) or CSV row per message; returns the PacketCounters seen, in order."""
    writer = None
    if header is not None:
        writer = csv.DictWriter(handle, fieldnames=header, restval="", lineterminator="\n")
        writer.writeheader()
    counters: list[int] = []
    with progress.task("writing messages", total=total) as update:
        for count, message in enumerate(messages, 1):
            _write_one(message, handle, writer, counters)
            if count % WRITE_BATCH == 0:
                update(count)
    return counters


def _write_one(
    message: MTData2Message, handle: IO[str], writer: csv.DictWriter[str] | None, counters: list[int]
) -> None:
    """One message as a JSON line (``writer`` None) or a CSV row; its PacketCounter kept in ``counters``."""
    from ..xsens.mtdata2 import to_jsonable

    if "PacketCounter" in message:
        counters.append(cast(int, message["PacketCounter"]))
    if writer is None:
        values = {name: to_jsonable(value) for name, value in message.items()}
        handle.write(json.dumps(values, separators=(",", ":")) + "\n")
    else:
        writer.writerow(
            {col: cell for name, value in message.items() for col, cell in flatten(name, value).items()}
        )


def summary_line(block: DecodedBlock, legacy: int, tracker: CounterTracker) -> str:
    """What was in the capture, for stderr."""
    undecoded_legacy = sum(frame.mid == MID.MTDATA for frame in block.other_frames) - legacy
    parts = [
        f"{block.n_messages} MTData2 messages",
        *([f"{legacy} legacy MTData messages"] if legacy else []),
        f"{len(block.other_frames) - legacy} other frames",
        f"{block.bad_checksums} bad checksums",
        f"{block.skipped_bytes} skipped bytes",
        f"{block.false_syncs} false syncs rejected",
        f"{block.unknown_ids} unknown identifiers",
        f"{tracker.gap_count} counter gaps ({tracker.lost} packets lost)",
    ]
    if block.malformed:
        parts.append(f"{block.malformed} malformed messages")
    if block.pending_bytes:
        parts.append(f"{block.pending_bytes} bytes of a truncated last frame")
    if undecoded_legacy:
        parts.append(
            f"{undecoded_legacy} legacy MTData frames not decoded: give --legacy-mode and --legacy-settings "
            "(the output mode and settings of the device)"
        )
    return ", ".join(parts)


def _log_summary(block: DecodedBlock) -> str:
    """What was in an MT Manager log, per device (``xsens.mtb.DecodedLog.summary``)."""
    from ..xsens.mtb import split_log

    return split_log(block).summary()


def parse_register(value: str | None) -> int | None:
    """typer parser for --legacy-mode/--legacy-settings: '0x0006', '6' or None."""
    if value is None:
        return None
    try:
        return int(value, 0)
    except ValueError:
        raise typer.BadParameter(f"{value!r} is not a number (e.g. 0x0006)") from None


@app.command("decode")
@handles_errors
def decode_command(
    capture: Annotated[Path, typer.Argument(help="Raw capture: the bytes as read from the serial port.")],
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="jsonl or csv.")
    ] = OutputFormat.jsonl,
    out: Annotated[
        Path | None,
        typer.Option("--out", callback=checked(new_file), help="Write here (a new file) instead of stdout."),
    ] = None,
    legacy_mode: Annotated[
        int | None,
        typer.Option("--legacy-mode", parser=parse_register, help="Legacy MTi-G OutputMode, e.g. 0x0006."),
    ] = None,
    legacy_settings: Annotated[
        int | None,
        typer.Option(
            "--legacy-settings", parser=parse_register, help="Legacy MTi-G OutputSettings, e.g. 0x1."
        ),
    ] = None,
) -> None:
    """Decode a raw Xsens capture: one JSON object (or CSV row) per message, in device units.

    MTData2 messages always; legacy MTData (2007-era MTi-G) when its output mode and settings are given.
    """
    from ..xsens.legacy import legacy_layout
    from ..xsens.timebase import CounterTracker

    if (legacy_mode is None) != (legacy_settings is None):
        raise InputError("give both --legacy-mode and --legacy-settings (see the device configuration)")
    if legacy_mode is not None:
        try:
            legacy_layout(legacy_mode, legacy_settings or 0)
        except ProtocolError as exc:
            raise InputError(str(exc)) from None
    data = read_capture(capture)
    log = is_log(capture, data)
    progress = TerminalProgress()  # where stderr is not a terminal: a line every 10 s, not a bar
    block = decode_all(data, progress, capture.name, log)
    if block.frames == 0:
        raise InputError(f"no Xbus frames in {capture} ({len(data)} bytes): is it a raw serial capture?")
    legacy = [] if legacy_mode is None else decode_legacy(block, legacy_mode, legacy_settings or 0)
    by_device = log and np.unique(block.bus_ids).size > 1  # an Awinda station's log: which device
    header = csv_header(block, legacy) if output_format is OutputFormat.csv else None
    if header is not None and by_device:
        header.insert(0, BUS_ID)
    with open_output(out) as handle:
        total = block.n_messages + len(legacy)
        counters = write_messages(in_stream_order(block, legacy, by_device), total, handle, header, progress)
    tracker = CounterTracker()
    tracker.update_many(np.array(counters, dtype=np.int64))
    err_console.print(
        f"{capture.name}: {_log_summary(block) if log else summary_line(block, len(legacy), tracker)}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )
