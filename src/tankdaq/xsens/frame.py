"""One Xbus frame: build, check and parse (LLCP §5.1).

standard: ``FA BID MID LEN DATA CS``; extended (more than 254 data bytes):
``FA BID MID FF LENH LENL DATA CS``. The checksum makes the sum of every byte after
the preamble, checksum included, a multiple of 256.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ProtocolError
from .constants import EXTENDED_LENGTH, MASTER_BID, MAX_DATA_LENGTH, MID, PREAMBLE


def _header(bid: int, mid: int, length: int) -> bytes:
    if length < EXTENDED_LENGTH:
        return bytes((PREAMBLE, bid, mid, length))
    return bytes((PREAMBLE, bid, mid, EXTENDED_LENGTH, length >> 8, length & 0xFF))


def build_frame(mid: int, payload: bytes = b"", bid: int = MASTER_BID) -> bytes:
    """The wire bytes of one message; the extended length form is chosen when the data needs it."""
    if len(payload) > MAX_DATA_LENGTH:
        raise ProtocolError(
            f"message data of {len(payload)} bytes exceeds the Xbus maximum of {MAX_DATA_LENGTH}"
        )
    if not (0 <= mid <= 0xFF and 0 <= bid <= 0xFF):
        raise ProtocolError(f"bus id 0x{bid:X} and message id 0x{mid:X} must each fit in one byte")
    body = _header(bid, mid, len(payload))[1:] + bytes(payload)
    return bytes((PREAMBLE,)) + body + bytes(((-sum(body)) & 0xFF,))


def checksum_ok(frame: bytes) -> bool:
    """True when the bytes after the preamble, checksum included, sum to 0 mod 256."""
    return len(frame) >= 5 and sum(frame[1:]) & 0xFF == 0


def frame_length(header: bytes) -> int | None:
    """Total frame length from its first 4 (or 6, extended) bytes; None if more header bytes are needed."""
    if len(header) < 4:
        return None
    if header[3] != EXTENDED_LENGTH:
        return 4 + header[3] + 1
    if len(header) < 6:
        return None
    return 6 + (header[4] << 8 | header[5]) + 1


@dataclass(frozen=True)
class Frame:
    """A checked Xbus message: bus id, message id and data bytes."""

    bid: int
    mid: int
    payload: bytes

    def to_bytes(self) -> bytes:
        """The wire form (with preamble, length and checksum)."""
        return build_frame(self.mid, self.payload, self.bid)

    @property
    def name(self) -> str:
        """The message id's name, or its hex value for ids tankdaq does not know."""
        try:
            return MID(self.mid).name
        except ValueError:
            return f"0x{self.mid:02X}"


def parse_frame(data: bytes) -> Frame:
    """Exactly one frame from ``data``: raises ProtocolError on a bad preamble, length or checksum."""
    data = bytes(data)
    if not data or data[0] != PREAMBLE:
        raise ProtocolError("not an Xbus frame: it must start with the preamble 0xFA")
    total = frame_length(data)
    if total is None or total != len(data):
        raise ProtocolError(f"Xbus frame length mismatch: header says {total} bytes, got {len(data)}")
    if total - 7 > MAX_DATA_LENGTH:
        raise ProtocolError(f"Xbus frame data exceeds the maximum of {MAX_DATA_LENGTH} bytes")
    if not checksum_ok(data):
        raise ProtocolError(f"Xbus frame checksum mismatch (frame {data.hex(' ')})")
    start = 6 if data[3] == EXTENDED_LENGTH else 4
    return Frame(bid=data[1], mid=data[2], payload=data[start:-1])
