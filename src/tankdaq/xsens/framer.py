"""Sequential byte-stream framer: the reference semantics every faster decoder must match.

A reference decoder: recordings, files and the live port are framed by ``frame_scan`` (through
``stream_decoder`` and ``column_decoder``), which the tests hold to this framer's results; this one frames
the device's replies during configuration (``device.link``) and the simulator's input.

Rules (reference §5, after xspublic ``findMessage``): look for 0xFA; read the length
(bounded by ``max_length``); wait while the frame is incomplete; on a bad checksum or an
impossible length advance ONE byte and rescan, so a real preamble inside a corrupted
frame is not lost. Bytes that end up in no frame are counted as skipped. Never raises.

Confirmation (an 8-bit checksum passes one false frame in 256): a frame that starts where
the previous one ended, with the same header (bus id, message id, length), is *trusted*: its
checksum is enough, so a steady stream is framed without delay. Any other candidate must be
confirmed: a master-device bus id and the next frame starting right after it; after a loss
of sync (bad checksum, skipped bytes) a *resync* must also be an MTData2 payload whose item
sizes add up (``confirm``). A candidate that fails is a *false sync* (counted) and the framer
steps one byte on, so a false header (a stray ``FA FF 36``, a corrupted length) never swallows
the intact frames behind it. While the bytes that decide have not arrived, the framer waits;
``flush`` (the line went quiet) accepts such a frame on what it has. ``finish`` (the stream
ended: the end of a file, a device that stopped) also gives up the candidates that can never be
complete, so a frame held behind one (a stray header just before the last frame) is found.
"""

from __future__ import annotations

from .constants import EXTENDED_LENGTH, MAX_DATA_LENGTH, MID, PREAMBLE
from .frame import Frame
from .mtdata2 import payload_well_formed

#: Bus ids a resync may land on: tankdaq addresses the device as master (0xFF); a stand-alone
#: MT also answers 0x01 with the id it was sent (reference §1.1).
RESYNC_BIDS = frozenset((0xFF, 0x01))
#: Every bus id: a log file (MT Manager's ``.mtb``) holds the frames of several devices (an Awinda
#: station's MTw sensors at bus ids 1-N), each a frame to keep, not a false sync.
ANY_BID = frozenset(range(0x01, 0x100))
MTDATA2 = int(MID.MTDATA2)


def confirm(
    buf: bytes | bytearray,
    start: int,
    header: int,
    stop: int,
    sync: bytes | None,
    final: bool,
    bids: frozenset[int] = RESYNC_BIDS,
) -> bool | None:
    """Is the checksum-valid candidate ``buf[start:stop]`` a real frame, in sync state ``sync``?

    True/False, or None while the bytes that decide are still to come (``final``: they never
    will, so a candidate that passes everything else is accepted). The next frame starts at
    ``stop`` when the byte there is a preamble, or when the two after it repeat this frame's
    bus and message ids (a corrupted preamble still leaves those).
    """
    bid, mid = buf[start + 1], buf[start + 2]
    trusted = sync is not None and buf[start : start + header] == sync
    if not trusted and bid not in bids:
        return False
    resync = sync is None
    if resync and mid == MTDATA2 and not payload_well_formed(bytes(buf[start + header : stop - 1])):
        return False
    end = len(buf)
    if stop < end and buf[stop] == PREAMBLE:
        return True
    if stop + 3 <= end:
        return buf[stop + 1] == bid and buf[stop + 2] == mid
    return True if final else None


class StreamFramer:
    """Incremental framer: ``feed`` bytes as they arrive, get the complete frames back."""

    def __init__(self, max_length: int = MAX_DATA_LENGTH, bids: frozenset[int] = RESYNC_BIDS) -> None:
        self.max_length = max_length
        self.bids = bids  # the bus ids a resync may land on (``ANY_BID`` for a log of several devices)
        self.frames = 0
        self.bad_checksums = 0
        self.skipped_bytes = 0
        self.false_syncs = 0
        self._buffer = bytearray()
        #: Sync state where the buffer starts: the header of the accepted frame that ended there,
        #: b"" at the start of a stream, None after a loss of sync.
        self.sync: bytes | None = b""

    @property
    def pending(self) -> int:
        """Bytes held back because they may start a frame that is not complete (or confirmed) yet."""
        return len(self._buffer)

    def take_pending(self) -> bytes:
        """Hand over the held-back bytes (another decoder takes the stream from here); the buffer empties."""
        held = bytes(self._buffer)
        self._buffer.clear()
        return held

    def feed(self, chunk: bytes) -> list[Frame]:
        """Append ``chunk`` and return every frame completed by it, in stream order."""
        self._buffer += chunk
        return self._scan(final=False)

    def flush(self) -> list[Frame]:
        """The line went quiet: accept a held frame that only lacks a successor."""
        return self._scan(final=True)

    def finish(self) -> list[Frame]:
        """The stream ended: as ``flush``, and an incomplete candidate is skipped, not waited for (its
        bytes never come), so the frames behind it are found. With no frame behind it, it is where the
        stream was cut: its bytes stay pending (not counted as skipped), as after ``flush``."""
        return self._scan(final=True, ended=True)

    def _scan(self, final: bool, ended: bool = False) -> list[Frame]:
        buf = self._buffer
        out: list[Frame] = []
        pos = 0
        end = len(buf)
        sync = self.sync
        cut: tuple[int, int, int, int, bytes | None] | None = None
        while True:
            start = buf.find(PREAMBLE, pos)
            if start < 0:
                start = end
            if start > pos:
                self.skipped_bytes += start - pos
                sync = None
                pos = start
            if pos >= end:
                break
            length, header = (buf[pos + 3], 4) if end - pos >= 4 else (-1, 4)
            if length == EXTENDED_LENGTH:
                length, header = (buf[pos + 4] << 8 | buf[pos + 5], 6) if end - pos >= 6 else (-1, 6)
            stop = pos + header + length + 1
            if length > self.max_length:
                self.skipped_bytes += 1
                pos += 1
                sync = None
                continue
            if length < 0 or stop > end:  # incomplete
                if not ended:
                    break
                # the stream ends inside it: where a file was cut, unless a frame is found behind it
                cut = cut or (pos, self.skipped_bytes, self.bad_checksums, self.false_syncs, sync)
                self.skipped_bytes += 1
                pos += 1
                sync = None
                continue
            if sum(buf[pos + 1 : stop]) & 0xFF:
                self.bad_checksums += 1
                self.skipped_bytes += 1
                pos += 1
                sync = None
                continue
            confirmed = confirm(buf, pos, header, stop, sync, final, self.bids)
            if confirmed is None:
                break
            if not confirmed:
                self.false_syncs += 1
                self.skipped_bytes += 1
                pos += 1
                sync = None
                continue
            out.append(Frame(bid=buf[pos + 1], mid=buf[pos + 2], payload=bytes(buf[pos + header : stop - 1])))
            sync = bytes(buf[pos : pos + header])
            pos = stop
            cut = None
        if cut is not None:  # nothing behind the cut frame: its bytes stay pending, as they were
            pos, self.skipped_bytes, self.bad_checksums, self.false_syncs, sync = cut
        del buf[:pos]
        self.sync = sync
        self.frames += len(out)
        return out
