"""Sequential byte-stream framer: the reference semantics every faster decoder must match.

Rules (reference §5, after xspublic ``findMessage``): look for 0xFA; read the length
(bounded by ``max_length``); wait while the frame is incomplete; on a bad checksum or an
impossible length advance ONE byte and rescan, so a real preamble inside a corrupted
frame is not lost. Bytes that end up in no frame are counted as skipped. Never raises.
"""

from __future__ import annotations

from .constants import EXTENDED_LENGTH, MAX_DATA_LENGTH, PREAMBLE
from .frame import Frame


class StreamFramer:
    """Incremental framer: ``feed`` bytes as they arrive, get the complete frames back."""

    def __init__(self, max_length: int = MAX_DATA_LENGTH) -> None:
        self.max_length = max_length
        self.frames = 0
        self.bad_checksums = 0
        self.skipped_bytes = 0
        self._buffer = bytearray()

    @property
    def pending(self) -> int:
        """Bytes held back because they may start a frame that is not complete yet."""
        return len(self._buffer)

    def feed(self, chunk: bytes) -> list[Frame]:
        """Append ``chunk`` and return every frame completed by it, in stream order."""
        buf = self._buffer
        buf += chunk
        out: list[Frame] = []
        pos = 0
        end = len(buf)
        while True:
            start = buf.find(PREAMBLE, pos)
            if start < 0:
                self.skipped_bytes += end - pos
                pos = end
                break
            self.skipped_bytes += start - pos
            pos = start
            if end - pos < 4:
                break
            length = buf[pos + 3]
            header = 4
            if length == EXTENDED_LENGTH:
                if end - pos < 6:
                    break
                length = buf[pos + 4] << 8 | buf[pos + 5]
                header = 6
            if length > self.max_length:
                self.skipped_bytes += 1
                pos += 1
                continue
            stop = pos + header + length + 1
            if stop > end:
                break
            if sum(buf[pos + 1 : stop]) & 0xFF:
                self.bad_checksums += 1
                self.skipped_bytes += 1
                pos += 1
                continue
            out.append(Frame(bid=buf[pos + 1], mid=buf[pos + 2], payload=bytes(buf[pos + header : stop - 1])))
            pos = stop
        del buf[:pos]
        self.frames += len(out)
        return out
