"""Rewrite a damaged recording (killed writer, full disk) into a valid, indexed MCAP file.

Like ``mcap recover``: read every record that survived, front to back, and
write it again through a fresh Writer, which adds the chunk indexes, summary
and footer the killed writer never wrote. Channel and schema ids are remapped;
messages keep their times, order and bytes; metadata and attachments are kept.
A recording's copy ends with its run metadata once more, saying how the decay ended:
``ended = recovered`` (partial: the decay's end is missing) over what the cut file said.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from .._version import __version__
from ..errors import BadRecordingInput, RecordingError
from ..records import DecayEnd
from . import schemas
from .naming import create_exclusive
from .record_scan import RecordScan

#: Progress callback: (bytes of the source read so far, total bytes).
Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class RecoverReport:
    """What a recovery saved. ``lossless``: every byte of the source was understood."""

    source: Path
    destination: Path | None
    messages: int
    chunks: int
    metadata: int
    attachments: int
    lossless: bool
    source_complete: bool
    damage: str | None

    @property
    def exit_code(self) -> int:
        """As ``mcap recover``: 0 lossless, 3 lossy, 1 nothing recovered."""
        if self.messages == 0:
            return 1
        return 0 if self.lossless else 3

    def summary(self) -> str:
        """One line for people."""
        if self.messages == 0:
            return (
                f"nothing recovered from {self.source}: no complete message in it ({self.damage or 'empty'})"
            )
        state = "complete file" if self.source_complete else f"truncated file ({self.damage})"
        loss = "nothing lost" if self.lossless else "the damaged tail was dropped"
        if self.source_complete and self.damage:  # closed, with garbled chunks in its middle
            state, loss = f"corrupted, not cut short: unreadable {self.damage}", "those chunks were dropped"
        return (
            f"recovered {self.messages} messages, {self.metadata} metadata records and "
            f"{self.attachments} attachments from {self.chunks} chunks of {self.source} "
            f"({state}; {loss}) into {self.destination}"
        )


def default_destination(src: Path) -> Path:
    """``run.mcap`` -> ``run.recovered.mcap`` (then ``-2`` ... if taken)."""
    return src.with_name(f"{src.stem}.recovered.mcap")


class _Rewriter:
    """Copies records into a fresh Writer, remapping schema and channel ids."""

    def __init__(self, writer: Writer) -> None:
        self.writer = writer
        self.schema_ids: dict[int, int] = {0: 0}
        self.channel_ids: dict[int, int] = {}
        self.messages = self.metadata = self.attachments = 0
        self.pending: list[Channel] = []
        self.run_metadata: dict[str, str] | None = None  # the last ``tankdaq.run`` record copied

    def add(self, record: object) -> None:
        if isinstance(record, Schema) and record.id not in self.schema_ids:
            self.schema_ids[record.id] = self.writer.register_schema(
                record.name, record.encoding, record.data
            )
        elif isinstance(record, Channel) and record.id not in self.channel_ids:
            self.channel_ids[record.id] = self.writer.register_channel(
                record.topic,
                record.message_encoding,
                self.schema_ids.get(record.schema_id, 0),
                record.metadata,
            )
        elif isinstance(record, Message) and record.channel_id in self.channel_ids:
            self.writer.add_message(
                self.channel_ids[record.channel_id],
                record.log_time,
                record.data,
                record.publish_time,
                record.sequence,
            )
            self.messages += 1
        elif isinstance(record, Metadata):
            self.writer.add_metadata(record.name, record.metadata)
            self.metadata += 1
            if record.name == schemas.RUN_METADATA_NAME:
                self.run_metadata = dict(record.metadata)
        elif isinstance(record, Attachment):
            self.writer.add_attachment(
                record.create_time, record.log_time, record.name, record.media_type, record.data
            )
            self.attachments += 1

    def mark_recovered(self) -> None:
        """A cut recording's copy: its run metadata again, saying how it ended (``recovered``)."""
        if self.run_metadata is not None:
            self.writer.add_metadata(
                schemas.RUN_METADATA_NAME, {**self.run_metadata, "ended": DecayEnd.RECOVERED.value}
            )


def recover(
    src: str | Path, dst: str | Path | None = None, progress: Progress | None = None
) -> RecoverReport:
    """Rewrite ``src`` into a valid MCAP at ``dst`` (default ``<name>.recovered.mcap``, never overwritten).

    An explicit ``dst`` that exists is refused; the default name gets ``-2``, ``-3`` ...
    Nothing is written when nothing can be recovered.
    """
    source = Path(src)
    scan = RecordScan(source)  # refuses missing, empty and non-MCAP files before anything is created
    if dst is not None and Path(dst).exists():
        raise BadRecordingInput(f"{dst} already exists; choose another --out (recover never overwrites)")
    target, fd = create_exclusive(Path(dst) if dst is not None else default_destination(source))
    ok = False
    try:
        with os.fdopen(fd, "wb") as out:
            writer = Writer(out, compression=CompressionType.ZSTD)
            writer.start(profile="", library=f"tankdaq {__version__} recover")
            rewriter = _Rewriter(writer)
            reported = -1
            for record in scan:
                rewriter.add(record)
                if progress is not None and scan.bytes_read != reported:  # once per chunk, not per message
                    reported = scan.bytes_read
                    progress(reported, scan.size)
            if not scan.complete:
                rewriter.mark_recovered()
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
        ok = rewriter.messages > 0
    except OSError as exc:
        raise RecordingError(f"cannot write {target}: {exc.strerror}") from None
    finally:
        if not ok:
            target.unlink(missing_ok=True)
    return RecoverReport(
        source=source,
        destination=target if ok else None,
        messages=rewriter.messages,
        chunks=scan.chunks,
        metadata=rewriter.metadata,
        attachments=rewriter.attachments,
        lossless=scan.clean_end,
        source_complete=scan.complete,
        damage=scan.damage or scan.corruption,
    )
