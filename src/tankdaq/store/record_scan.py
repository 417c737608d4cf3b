"""Every record of an MCAP file front to back, stopping quietly where a torn tail begins.

The reading path that needs no summary: ``store.reader`` reads files cut short through it, and
``store.recover`` rewrites them from it. Apart from the reader so recovery does not depend on how
a whole recording is assembled.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import zstandard
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.records import Chunk, Footer, Header, McapRecord
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import MCAP0_MAGIC

from ..errors import BadRecordingInput
from ..validation import input_file

#: What a torn tail can raise inside mcap: short reads, bad lengths, CRC mismatches, broken zstd frames.
MCAP_DAMAGE = (McapError, ValueError, struct.error, zstandard.ZstdError, RuntimeError)


class RecordScan:
    """Every record of an MCAP file in file order, stopping quietly where a damaged tail begins.

    Chunks are opened here (not inside StreamReader) so a torn last chunk is
    noticed as damage and counted. After iterating: ``complete`` (the footer was
    read), ``clean_end`` (the file ended on a record boundary, so nothing on disk
    was lost), ``damage`` (what stopped the scan, or None), ``chunks``,
    ``bytes_read`` and ``size``.
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

    @property
    def clean_end(self) -> bool:
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
                    self.damage = "file ends early" if isinstance(exc, EndOfFile) else str(exc)
                    break
                self.chunks += isinstance(record, Chunk)
                self.complete = isinstance(record, Footer)
                yield from inner
            self.bytes_read = stream.tell() if self.complete else self.bytes_read


def is_mcap(data: bytes) -> bool:
    """Whether these bytes (a file's start is enough) open an MCAP file: lets callers that read raw
    captures send a recording to the commands that read recordings."""
    return data.startswith(MCAP0_MAGIC)
