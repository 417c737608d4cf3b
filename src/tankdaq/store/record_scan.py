"""Every record of an MCAP file front to back, stopping quietly where a torn tail begins, and stepping
over chunks garbled in the middle of a closed file.

The reading path that needs no summary: ``store.reader`` reads files cut short through it, and
``store.recover`` rewrites them from it. Apart from the reader so recovery does not depend on how
a whole recording is assembled.

Corruption is told from truncation: a file cut short has no footer, and its scan ends where the damage
begins. A file whose footer and summary are intact but one of whose chunks fails its CRC check or
decompression (a bad sector) was closed by its writer: the scan names the chunk (``DamagedChunk``: its
number, bytes and time range, from the summary's chunk index), seeks past it to the next record the
summary knows, and reads every intact chunk after it.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import zstandard
from mcap.exceptions import EndOfFile, InvalidMagic, McapError, RecordLengthLimitExceeded
from mcap.reader import SeekingReader
from mcap.records import Chunk, ChunkIndex, Footer, Header, McapRecord
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import MCAP0_MAGIC

from ..config.validation import input_file
from ..errors import BadRecordingInput

#: What a torn tail can raise inside mcap: short reads, bad lengths, CRC mismatches, broken zstd frames.
MCAP_DAMAGE = (McapError, ValueError, struct.error, zstandard.ZstdError, RuntimeError)


#: The footer record at the end of an MCAP file: opcode, length, summary start, summary offset start, CRC.
_FOOTER = struct.Struct("<BQQQI")


@dataclass(frozen=True)
class DamagedChunk:
    """A chunk of a closed file that cannot be read (its CRC or its compression fails): where it is and
    which time its messages covered (log time, ns), from the summary's chunk index."""

    number: int  # 1-based, in file order
    chunks: int  # in the file
    offset: int
    length: int
    start_ns: int
    end_ns: int
    why: str

    def describe(self, origin_ns: int) -> str:
        """``chunk 3 of 9 (bytes 1000-2000, 4.0-6.0 s after the first message)``."""
        start, end = ((t - origin_ns) / 1e9 for t in (self.start_ns, self.end_ns))
        return (
            f"chunk {self.number} of {self.chunks} (bytes {self.offset}-{self.offset + self.length}, "
            f"{start:.1f}-{end:.1f} s after the first message)"
        )


@dataclass(frozen=True)
class _Index:
    """What a closed file's summary says of where its records are: chunks in file order, and every offset
    a scan may resume at after damage (chunks, metadata, attachments, the summary itself)."""

    chunks: list[ChunkIndex]
    resume_at: list[int]

    @classmethod
    def of(cls, stream: BinaryIO, size: int) -> _Index | None:
        """The index of a file with an intact footer and summary; None for any other (cut short)."""
        try:
            stream.seek(0)
            summary = SeekingReader(stream, validate_crcs=True).get_summary()
            stream.seek(size - len(MCAP0_MAGIC) - _FOOTER.size)
            _, _, summary_start, _, _ = _FOOTER.unpack(stream.read(_FOOTER.size))
        except (*MCAP_DAMAGE, InvalidMagic, OSError):
            return None
        if summary is None or not summary.chunk_indexes:
            return None
        chunks = sorted(summary.chunk_indexes, key=lambda index: index.chunk_start_offset)
        offsets = [index.chunk_start_offset for index in chunks] + [summary_start]
        offsets += [m.offset for m in summary.metadata_indexes] + [
            a.offset for a in summary.attachment_indexes
        ]
        return cls(chunks, sorted(set(offsets)))

    def damaged(self, offset: int, why: str) -> DamagedChunk | None:
        """The chunk starting at ``offset``; None when no chunk does (the damage is between chunks)."""
        for number, index in enumerate(self.chunks, start=1):
            if index.chunk_start_offset == offset:
                return DamagedChunk(
                    number, len(self.chunks), offset, index.chunk_length, index.message_start_time,
                    index.message_end_time, why,
                )  # fmt: skip
        return None

    @property
    def origin_ns(self) -> int:
        return min(index.message_start_time for index in self.chunks)


class RecordScan:
    """Every record of an MCAP file in file order, stopping quietly where a damaged tail begins.

    Chunks are opened here (not inside StreamReader) so a torn last chunk is
    noticed as damage and counted. After iterating: ``complete`` (the footer was
    read), ``clean_end`` (the file ended on a record boundary, so nothing on disk
    was lost), ``damage`` (what stopped the scan, or None), ``corrupted`` (the
    chunks of a closed file that were stepped over, and ``corruption``, the line
    naming them), ``chunks``, ``bytes_read`` and ``size``.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = input_file(Path(path), "recording", error=BadRecordingInput)
        self.size = self.path.stat().st_size
        if self.size == 0:
            raise BadRecordingInput(f"{self.path} is empty: the writer died before writing anything")
        self.complete = False
        self.damage: str | None = None
        self.bytes_read = 0
        self.chunks = 0
        self.corrupted: list[DamagedChunk] = []
        self._between: list[str] = []  # damage outside any chunk: "bytes A-B: why"
        self._origin_ns = 0

    @property
    def corruption(self) -> str | None:
        """The damaged chunks of a closed file in one phrase (None when there are none)."""
        parts = [f"{c.describe(self._origin_ns)}: {c.why}" for c in self.corrupted] + self._between
        return "; ".join(parts) or None

    @property
    def clean_end(self) -> bool:
        if self.corruption is not None:
            return False
        return self.complete or (self.damage is not None and self.bytes_read == self.size)

    def __iter__(self) -> Iterator[McapRecord]:
        with self.path.open("rb") as stream:
            if not is_mcap(stream.read(len(MCAP0_MAGIC))):
                raise BadRecordingInput(
                    f"{self.path} is not an MCAP file (it does not start with the MCAP magic bytes)"
                )
            stream.seek(0)
            records = StreamReader(stream, emit_chunks=True, validate_crcs=True).records
            try:
                first = next(records)
            except (*MCAP_DAMAGE, InvalidMagic, EOFError) as exc:
                short = isinstance(exc, EndOfFile | struct.error | EOFError) or not str(exc)
                why = "" if short else f" ({exc})"
                raise BadRecordingInput(
                    f"{self.path} is an MCAP file cut short at {self.size} bytes, before its first record "
                    f"ended{why}: nothing to read"
                ) from None
            if not isinstance(first, Header):
                raise BadRecordingInput(f"{self.path} is not a readable MCAP file: no header record")
            yield first
            index: _Index | None = None
            read: set[int] = set()  # where the chunks read whole start
            while True:
                self.bytes_read = stream.tell()
                try:
                    record = next(records)
                    inner = (
                        breakup_chunk(record, validate_crc=True) if isinstance(record, Chunk) else [record]
                    )
                except StopIteration:
                    break
                except MCAP_DAMAGE as exc:
                    why = _why(exc)
                    index = index or _Index.of(stream, self.size)
                    resume = self._step_over(index, why) if index is not None else None
                    if resume is None:
                        self.damage = why
                        break
                    stream.seek(resume)
                    records = StreamReader(
                        stream, skip_magic=True, emit_chunks=True, validate_crcs=True
                    ).records
                    continue
                if isinstance(record, Chunk):
                    self.chunks += 1
                    read.add(self.bytes_read)
                self.complete = isinstance(record, Footer)
                yield from inner
            self.bytes_read = stream.tell() if self.complete else self.bytes_read
            if index is not None and self.complete:  # a garbled record header may have hidden chunks
                self._note_missed(index, read)

    def _step_over(self, index: _Index, why: str) -> int | None:
        """Where to read on after damage at ``bytes_read`` in a closed file (the next record its summary
        knows), the damage noted; None when there is nowhere (the damage is in the summary itself)."""
        resume = next((offset for offset in index.resume_at if offset > self.bytes_read), None)
        if resume is None:
            return None
        self._origin_ns = index.origin_ns
        chunk = index.damaged(self.bytes_read, why)
        if chunk is not None:
            self.corrupted.append(chunk)
        else:
            self._between.append(f"bytes {self.bytes_read}-{resume}: {why}")
        return resume

    def _note_missed(self, index: _Index, read: set[int]) -> None:
        """Chunks of the index the scan never read whole nor named (passed over inside garbled bytes)."""
        named = {chunk.offset for chunk in self.corrupted}
        for index_entry in index.chunks:
            offset = index_entry.chunk_start_offset
            if offset not in read and offset not in named:
                missed = index.damaged(offset, "passed over inside garbled bytes")
                if missed is not None:
                    self.corrupted.append(missed)
        self.corrupted.sort(key=lambda chunk: chunk.offset)


def _why(exc: Exception) -> str:
    """The damage in a few words (mcap's own text carries CRC values, which tell a person nothing)."""
    if isinstance(exc, EndOfFile):
        return "file ends early"
    if isinstance(exc, RecordLengthLimitExceeded):
        return "its record header is garbled"
    if "crc" in str(exc).lower():
        return "its CRC check fails"
    if isinstance(exc, zstandard.ZstdError):
        return "its compressed data is garbled"
    return str(exc) or type(exc).__name__


def is_mcap(data: bytes) -> bool:
    """Whether these bytes (a file's start is enough) open an MCAP file: lets callers that read raw
    captures send a recording to the commands that read recordings."""
    return data.startswith(MCAP0_MAGIC)
