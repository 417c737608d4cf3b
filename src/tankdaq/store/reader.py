"""Read tankdaq recordings back: samples in SI, raw bytes for re-decoding, events, fits, metadata.

``read_recording`` first tries the index: a complete file with sample blocks
(``/samples/blocks``, written beside the per-sample JSON since tankdaq 0.1)
reads only its small chunks of blocks, events and fits, through the summary.
Every other file goes through ``store.record_scan.RecordScan``, which reads the file front to
back with mcap's StreamReader. That path does not need the summary at the end
of the file, so a file whose writer was killed (no summary, maybe a torn last
chunk) reads up to its last complete chunk instead of failing, a closed file with a
chunk garbled in its middle (a bad sector) reads every other chunk and names the bad
one (``Recording.corruption``), and a file recorded before the blocks reads its
per-sample JSON.
"""

from __future__ import annotations

import itertools
import json
import math
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import InvalidMagic
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Chunk, Message, Metadata

from ..config.hulls import parse_draft
from ..errors import BadRecordingInput, InputError
from ..records import DecayEnd, DecayRun
from ..samples import AXIS_FIELDS, StatusTally
from . import schemas
from .record_scan import MCAP_DAMAGE, RecordScan
from .schemas import EventKind


@dataclass
class StoredRecording:
    """Everything in one tankdaq recording, samples already back in SI units.

    ``raw_chunks`` (``(host ns, bytes)`` of ``/xsens/raw``) is read on first use when
    the samples came from the blocks: most readers never need the raw bytes.
    """

    path: Path
    metadata: dict[str, str]
    samples: np.ndarray
    _raw_chunks: list[tuple[int, bytes]] | None
    events: list[dict[str, Any]]
    fits: list[dict[str, Any]]
    attachments: dict[str, bytes]
    channel_metadata: dict[str, dict[str, str]]
    complete: bool
    release_index: int | None = None
    metadata_history: list[dict[str, str]] = field(default_factory=list)
    damage: str | None = None  # what stopped the reading early, when something did
    corruption: str | None = None  # the chunks of a closed file that could not be read, when any

    @property
    def notice(self) -> str | None:
        """The one line to print when something of the file is missing: damaged chunks, or a cut end."""
        if self.corruption is not None:
            return corruption_notice(self.path, self.corruption)
        return truncation_notice(self.path, self.damage) if self.truncated else None

    @property
    def truncated(self) -> bool:
        """The file was never closed (no footer): what followed its last complete chunk is missing."""
        return not self.complete

    @property
    def ended(self) -> DecayEnd:
        """How the recorded decay ended: ``CUT`` without a footer, else the final metadata's ``ended`` (a
        file before it: its ``settle_reason``; a word tankdaq does not know: ``STOPPED``, partial). A
        closed file that says neither was written whole by a program (a simulation): ``SETTLED``."""
        if not self.complete:
            return DecayEnd.CUT
        said = self.metadata.get("ended", self.metadata.get("settle_reason"))
        if said is None:
            return DecayEnd.SETTLED
        return DecayEnd.of_settle_reason(said) or DecayEnd.STOPPED

    @property
    def raw_chunks(self) -> list[tuple[int, bytes]]:
        if self._raw_chunks is None:
            self._raw_chunks = list(iter_raw_chunks(self.path))
        return self._raw_chunks

    @property
    def axis(self) -> str:
        return self.metadata.get("axis", "roll")

    @property
    def run_config(self) -> dict[str, Any]:
        raw = self.attachments.get(schemas.CONFIG_ATTACHMENT_NAME)
        return json.loads(raw) if raw else {}


def _check_tankdaq(path: Path, channels: dict[int, Channel], has_run_metadata: bool) -> None:
    topics = {channel.topic for channel in channels.values()}
    if not topics and has_run_metadata:
        raise BadRecordingInput(
            f"{path} is a tankdaq recording cut short before its first data reached the disk: nothing to read"
        )
    if not topics & {schemas.TOPIC_SAMPLES, schemas.TOPIC_RAW}:
        found = ", ".join(sorted(topics)) or "no channels"
        raise BadRecordingInput(
            f"{path} is an MCAP file but not a tankdaq recording (it has {found}, not "
            f"{schemas.TOPIC_SAMPLES} or {schemas.TOPIC_RAW})"
        )
    if not has_run_metadata:  # tankdaq writes its run metadata before the first chunk reaches the disk
        raise BadRecordingInput(
            f"{path} is an MCAP file but not a tankdaq recording (it has {', '.join(sorted(topics))} but no "
            f"{schemas.RUN_METADATA_NAME} metadata: written by another tool)"
        )


def _release_times(events: list[dict[str, Any]]) -> list[float]:
    return sorted(e["t_s"] for e in events if e.get("kind") == EventKind.RELEASE and e.get("t_s") is not None)


def release_u95_of(events: list[dict[str, Any]], t_s: float) -> float | None:
    """The 95 % half-width (s) of the release at ``t_s`` as its event says it; None: unknown (a file written
    before the interval, or a release the detector could not bracket), never zero."""
    for event in events:
        if event.get("kind") == EventKind.RELEASE and event.get("t_s") == t_s:
            value = (event.get("data") or {}).get("release_u95_s")
            return float(value) if isinstance(value, int | float) and math.isfinite(value) else None
    return None


def _release_index(samples: np.ndarray, events: list[dict[str, Any]]) -> int | None:
    releases = _release_times(events)
    if not releases or samples.size == 0:
        return None
    index = int(np.searchsorted(samples["t"], releases[0], side="left"))
    return index if index < samples.size else None


def read_recording(path: str | Path) -> StoredRecording:
    """Read a whole recording (also a truncated one); raise BadRecordingInput if it is not one."""
    return _read_indexed(Path(path)) or _read_scanned(path)


def _read_indexed(path: Path) -> StoredRecording | None:
    """The recording from its summary and sample blocks; None when the file has no complete blocks.

    Blocks count as complete when they hold as many samples as ``/samples`` has
    messages (the summary's statistics): a file rewritten by ``recover`` after a
    kill may have lost a block whose samples survived, and then reads by scan.
    """
    if not path.is_file():
        return None
    with path.open("rb") as stream:
        try:  # anything not plainly a complete MCAP file is left to the scan, which says what is wrong
            reader = SeekingReader(stream, validate_crcs=True)
            summary = reader.get_summary()
        except (*MCAP_DAMAGE, InvalidMagic, OSError):  # OSError: a file shorter than a footer seeks before 0
            return None
        if summary is None or summary.statistics is None:
            return None
        topics = {channel.topic: channel.id for channel in summary.channels.values()}
        if schemas.TOPIC_SAMPLE_BLOCKS not in topics:
            return None
        blocks: list[bytes] = []
        events: list[dict[str, Any]] = []
        fits: list[dict[str, Any]] = []
        try:
            for _, channel, message in reader.iter_messages(
                topics=[schemas.TOPIC_SAMPLE_BLOCKS, schemas.TOPIC_EVENTS, schemas.TOPIC_FIT],
                log_time_order=False,
            ):
                if channel.topic == schemas.TOPIC_SAMPLE_BLOCKS:
                    blocks.append(message.data)
                else:
                    (events if channel.topic == schemas.TOPIC_EVENTS else fits).append(
                        json.loads(message.data)
                    )
            history = [
                dict(m.metadata) for m in reader.iter_metadata() if m.name == schemas.RUN_METADATA_NAME
            ]
            attachments = {a.name: a.data for a in reader.iter_attachments()}
        except MCAP_DAMAGE:
            return None
    samples = schemas.samples_from_blocks(blocks)
    if samples.size != summary.statistics.channel_message_counts.get(
        topics.get(schemas.TOPIC_SAMPLES, -1), 0
    ):
        return None
    channels = summary.channels.values()
    return _assemble(path, samples, None, events, fits, attachments, channels, history, complete=True)


def _read_scanned(path: str | Path) -> StoredRecording:
    """The recording read front to back: files cut short, and files without sample blocks."""
    scan = RecordScan(path)
    channels: dict[int, Channel] = {}
    sample_payloads: list[bytes] = []
    sample_stamps: list[int] = []
    raw_chunks: list[tuple[int, bytes]] = []
    events: list[dict[str, Any]] = []
    fits: list[dict[str, Any]] = []
    attachments: dict[str, bytes] = {}
    history: list[dict[str, str]] = []
    for record in scan:
        if isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message) and record.channel_id in channels:
            topic = channels[record.channel_id].topic
            if topic == schemas.TOPIC_SAMPLES:
                sample_payloads.append(record.data)
                sample_stamps.append(record.log_time)
            elif topic == schemas.TOPIC_RAW:
                raw_chunks.append((record.log_time, record.data))
            elif topic == schemas.TOPIC_EVENTS:
                events.append(json.loads(record.data))
            elif topic == schemas.TOPIC_FIT:
                fits.append(json.loads(record.data))
        elif isinstance(record, Metadata) and record.name == schemas.RUN_METADATA_NAME:
            history.append(dict(record.metadata))
        elif isinstance(record, Attachment):
            attachments[record.name] = record.data
    path = Path(path)
    _check_tankdaq(path, channels, bool(history))
    try:
        samples = schemas.samples_from_json(sample_payloads, sample_stamps)
    except (json.JSONDecodeError, TypeError, ValueError) as exc:
        raise BadRecordingInput(f"{path}: {schemas.TOPIC_SAMPLES} holds malformed JSON ({exc})") from None
    return _assemble(
        path, samples, raw_chunks, events, fits, attachments, channels.values(), history, scan.complete,
        scan.damage, scan.corruption,
    )  # fmt: skip


def _assemble(
    path: Path,
    samples: np.ndarray,
    raw_chunks: list[tuple[int, bytes]] | None,
    events: list[dict[str, Any]],
    fits: list[dict[str, Any]],
    attachments: dict[str, bytes],
    channels: Iterable[Channel],
    history: list[dict[str, str]],
    complete: bool,
    damage: str | None = None,
    corruption: str | None = None,
) -> StoredRecording:
    """The Recording from what either reading path found (the last ``tankdaq.run`` record is the metadata)."""
    return StoredRecording(
        path=path,
        metadata=history[-1] if history else {},
        samples=samples,
        _raw_chunks=raw_chunks,
        events=events,
        fits=fits,
        attachments=attachments,
        channel_metadata={c.topic: dict(c.metadata) for c in channels},
        complete=complete,
        release_index=_release_index(samples, events),
        metadata_history=history,
        damage=damage,
        corruption=corruption,
    )


def corruption_notice(path: str | Path, corruption: str) -> str:
    """The one line every command that reads a recording prints when chunks in its middle are garbled."""
    return (
        f"warning: {path} is corrupted, not cut short (its writer closed it; its footer is intact): "
        f"unreadable {corruption}; every other chunk was read, and results cover only what is there"
    )


def truncation_notice(path: str | Path, damage: str | None = None) -> str:
    """The one line every command that reads a recording prints when the recording is cut short."""
    why = f" ({damage})" if damage and damage != "file ends early" else ""
    return (
        f"warning: {path} is cut short{why}: its writer never closed it, so the end of the test is "
        f"missing and results cover only what is there; `tankdaq recover {path}` rewrites it as a valid file"
    )


def iter_raw_chunks(path: str | Path) -> Iterator[tuple[int, bytes]]:
    """``(host arrival ns, bytes)`` of ``/xsens/raw`` in file order, for replay through a decoder."""
    indexed = _indexed_raw_chunks(Path(path))
    if indexed is not None:
        yield from indexed
        return
    scan = RecordScan(path)
    raw_channels: set[int] = set()
    seen_channels: dict[int, Channel] = {}
    has_run_metadata = False
    for record in scan:
        has_run_metadata |= isinstance(record, Metadata) and record.name == schemas.RUN_METADATA_NAME
        if isinstance(record, Channel):
            seen_channels[record.id] = record
            if record.topic == schemas.TOPIC_RAW:
                raw_channels.add(record.id)
        elif isinstance(record, Message) and record.channel_id in raw_channels:
            yield record.log_time, record.data
    _check_tankdaq(scan.path, seen_channels, has_run_metadata)


_MESSAGE_HEADER = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


def _indexed_raw_chunks(path: Path) -> list[tuple[int, bytes]] | None:
    """The raw messages of a complete file through its chunk index; None when it has no usable index.

    Only the chunks holding raw bytes are opened, and their records are walked by
    opcode and length, picking the raw channel's messages without building the
    others (the per-sample JSON is most of every chunk).
    """
    if not path.is_file():
        return None
    with path.open("rb") as stream:
        try:
            summary = SeekingReader(stream, validate_crcs=True).get_summary()
        except (*MCAP_DAMAGE, InvalidMagic, OSError):  # OSError: a file shorter than a footer seeks before 0
            return None
        if summary is None:
            return None
        raw_ids = {c.id for c in summary.channels.values() if c.topic == schemas.TOPIC_RAW}
        found: list[tuple[int, bytes]] = []
        for index in sorted(summary.chunk_indexes, key=lambda i: i.chunk_start_offset):
            if index.message_index_offsets and not raw_ids & set(index.message_index_offsets):
                continue
            stream.seek(index.chunk_start_offset + 1 + 8)  # past the record's opcode and length
            try:
                chunk = Chunk.read(ReadDataStream(stream))
                data = _chunk_data(chunk)
            except MCAP_DAMAGE:
                return None
            if data is None:
                return None
            found += _messages_of(data, raw_ids)
    return found


def _chunk_data(chunk: Chunk) -> bytes | None:
    """The chunk's records, decompressed and CRC-checked (None for a compression tankdaq does not write)."""
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "":
        data = chunk.data
    else:
        return None
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ValueError("chunk CRC mismatch")
    return data


def _messages_of(records: bytes, channel_ids: set[int]) -> list[tuple[int, bytes]]:
    """(log time, data) of the messages on ``channel_ids`` among a chunk's records."""
    out = []
    position, end = 0, len(records)
    while position < end:
        opcode = records[position]
        (length,) = struct.unpack_from("<Q", records, position + 1)
        body = position + 9
        if opcode == Opcode.MESSAGE:
            channel_id, _, log_time, _ = _MESSAGE_HEADER.unpack_from(records, body)
            if channel_id in channel_ids:
                out.append((log_time, records[body + _MESSAGE_HEADER.size : body + length]))
        position = body + length
    return out


def _finite_increasing(t: np.ndarray, *columns: np.ndarray) -> np.ndarray:
    """Mask of rows usable for identification: all finite, time strictly increasing."""
    keep = np.isfinite(t)
    for column in columns:
        keep &= np.isfinite(column)
    indices = np.flatnonzero(keep)
    if indices.size:
        running_max = np.maximum.accumulate(t[indices])
        increasing = np.concatenate([[True], t[indices][1:] > running_max[:-1]])
        keep[indices[~increasing]] = False
    return keep


def read_decay_runs(path: str | Path, axis: str | None = None) -> list[DecayRun]:
    """The decays of a recording: from each release event to the next one (or the end).

    The axis comes from the file's metadata unless given; the rate is the gyro's.
    Rows with NaN (dropouts) are left out; ``meta`` says what was dropped. Samples the status word
    flags after the release (a sensor clipped, the orientation not valid: ``samples.StatusTally``) are
    the run's ``excluded`` (fits leave them out), with one line in ``meta["excluded_why"]``.
    """
    recording = read_recording(path)
    axis = axis or recording.axis
    if axis not in AXIS_FIELDS:
        raise InputError(f"axis {axis!r} not understood; use one of: {', '.join(AXIS_FIELDS)}")
    releases = _release_times(recording.events)
    if not releases:
        raise BadRecordingInput(
            f"{recording.path} holds no release event (the recording stopped before a release was detected)"
        )
    samples = recording.samples
    angle_field, rate_field = AXIS_FIELDS[axis]
    other_axis = next(name for name in AXIS_FIELDS if name != axis)
    other_angle, other_rate = AXIS_FIELDS[other_axis]
    runs: list[DecayRun] = []
    bounds = [*releases, np.inf]
    for number, (start, stop) in enumerate(itertools.pairwise(bounds), start=1):
        part = samples[(samples["t"] >= start) & (samples["t"] < stop)]
        rated = bool(np.isfinite(part[rate_field]).any())  # no rate at all: a decay imported without one
        keep = _finite_increasing(part["t"], part[angle_field], *([part[rate_field]] if rated else []))
        part_kept = part[keep]
        if part_kept.size < 2:
            raise BadRecordingInput(
                f"{recording.path}: release {number} at t = {start:.3f} s has no usable samples after it"
            )
        tally = StatusTally(start)
        since = bounds[number - 2] if number > 1 else -np.inf  # the tilt: back to the previous release
        before = samples[(samples["t"] < start) & (samples["t"] >= since)]
        tally.add(before)
        excluded = tally.add(part_kept)
        runs.append(
            DecayRun(
                t=part_kept["t"],
                angle=part_kept[angle_field],
                rate=part_kept[rate_field] if rated else None,
                axis=axis,
                name=recording.path.stem if len(releases) == 1 else f"{recording.path.stem}#{number}",
                channels={
                    f"other_angle_{other_axis}": part_kept[other_angle],
                    f"other_rate_{other_axis}": part_kept[other_rate],
                    "acc_x_m_s2": part_kept["ax"],
                    "acc_y_m_s2": part_kept["ay"],
                    "acc_z_m_s2": part_kept["az"],
                },
                meta=_run_meta(
                    recording,
                    axis,
                    start,
                    dropped=int(part.size - part_kept.size),
                    tally=tally,
                    last_t_s=float(part_kept["t"][-1]),
                ),
                excluded=excluded if excluded.any() else None,
            )
        )
    return runs


def _run_meta(
    recording: StoredRecording,
    axis: str,
    release_t_s: float,
    dropped: int,
    tally: StatusTally,
    last_t_s: float,
) -> dict[str, object]:
    meta = recording.metadata
    out: dict[str, object] = {
        "file": str(recording.path),
        "hull": meta.get("hull"),
        "axis": axis,
        "release_t_s": release_t_s,
        "release_u95_s": release_u95_of(recording.events, release_t_s),
        "dropped_samples": dropped,
        "complete_file": recording.complete,
        "truncation": recording.notice,  # what of the file is missing: a cut end, or corrupted chunks
        "status_flags": tally.metadata(),
    }
    if tally.flagged_after:
        out["excluded_why"] = tally.describe_after()
    if release_t_s == max(_release_times(recording.events)):  # the file's end is its last decay's
        out["ended"] = recording.ended
        out["ended_after_s"] = last_t_s - release_t_s
    if "draft" in meta:
        out["draft"] = parse_draft(meta["draft"])
    for key in ("angle_nominal_deg", "angle_initial_deg", "sample_rate_hz", "speed_m_s"):
        if key in meta:
            out[key] = float(meta[key])
    for key in ("device_id", "product_code", "operator", "note"):
        if key in meta:
            out[key] = meta[key]
    return out


__all__ = [
    "StoredRecording",
    "corruption_notice",
    "iter_raw_chunks",
    "read_decay_runs",
    "read_recording",
    "truncation_notice",
]
