"""Incremental decoding of a live byte stream on the batch machinery (identical results).

Each ``feed`` decodes the complete frames of (held-back tail + new chunk) with
``column_decoder.decode_buffer`` and keeps the bytes that may start an incomplete frame, exactly as
``StreamFramer`` does (including whether they start in sync), so any chunking of a stream
gives the same frames, counters and values as decoding it in one piece (then ``flush``).
"""

from __future__ import annotations

import numpy as np

from .column_decoder import DecodedBlock, decode_buffer
from .constants import MAX_DATA_LENGTH
from .framer import RESYNC_BIDS
from .layouts import LayoutCache


class StreamDecoder:
    """Feed raw serial chunks, get ``DecodedBlock``s; running totals in the counter attributes."""

    def __init__(self, max_length: int = MAX_DATA_LENGTH, bids: frozenset[int] = RESYNC_BIDS) -> None:
        self.max_length = max_length
        self.bids = bids  # the bus ids a resync may land on (``framer.ANY_BID``: a log of several devices)
        self.frames = 0
        self.messages = 0
        self.bad_checksums = 0
        self.skipped_bytes = 0
        self.malformed = 0
        self.unknown_ids = 0
        self.false_syncs = 0
        self._tail = np.empty(0, dtype=np.uint8)
        self._sync: bytes | None = b""
        self._layouts = LayoutCache()

    @property
    def pending(self) -> int:
        """Bytes held back because they may start a frame that is not complete yet."""
        return self._tail.size

    def feed(self, chunk: bytes) -> DecodedBlock:
        """Decode what ``chunk`` completes; frame indices in the block count from this call."""
        incoming = np.frombuffer(chunk, dtype=np.uint8)
        return self._decode(np.concatenate((self._tail, incoming)) if self._tail.size else incoming, False)

    def flush(self) -> DecodedBlock:
        """The line went quiet: decode a held frame that only lacks a successor."""
        return self._decode(self._tail, True)

    def finish(self) -> DecodedBlock:
        """The stream ended (a file's end, a device that stopped): as ``flush``, and the frames held
        behind a candidate that can never be complete are decoded too (``StreamFramer.finish``)."""
        return self._decode(self._tail, True, ended=True)

    def _decode(self, buf: np.ndarray, final: bool, ended: bool = False) -> DecodedBlock:
        block = decode_buffer(
            buf, self.max_length, self._layouts, sync=self._sync, final=final, carried_below=self._tail.size,
            ended=ended, bids=self.bids,
        )  # fmt: skip
        self._tail = buf[buf.size - block.pending_bytes :].copy()
        self._sync = block.sync
        self.frames += block.frames
        self.messages += block.n_messages
        self.bad_checksums += block.bad_checksums
        self.skipped_bytes += block.skipped_bytes
        self.false_syncs += block.false_syncs
        self.malformed += block.malformed
        self.unknown_ids += block.unknown_ids
        return block
