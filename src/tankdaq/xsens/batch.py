"""Vectorised decoding of raw Xbus captures into columns (numpy), with the framer's exact semantics.

A per-message Python parser manages ~1e5 frames/s; a long capture needs array code:

1. every 0xFA is a candidate frame start; lengths and checksums are checked for all
   candidates at once (row sums of equal-length candidates, or a mod-256 running sum);
2. the frames the sequential framer accepts (the first valid frame at or after the end of
   the previous one) are chosen by following a ``next`` pointer, in bulk over the runs where
   the next frame is simply the next valid candidate;
3. MTData2 frames are grouped by item layout: a layout is learnt from one frame, and every
   frame of the same length whose item headers sit at the same offsets with the same bytes
   has, by construction, the same layout. Each layout is a numpy structured dtype, so all its
   fields are read with one gather and big-endian views.

The result is a ``DecodedBlock``: per output name an array (one row per MTData2 message) and
a presence mask, the counters, and the non-MTData2 frames (acks, errors) as ``Frame`` objects.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import ProtocolError
from ..samples import empty_samples
from .constants import EXTENDED_LENGTH, MAX_DATA_LENGTH, MID, PREAMBLE
from .frame import Frame, frame_length
from .framer import RESYNC_BIDS
from .mtdata2 import (
    FP1220_SCALE,
    FP1632_SCALE,
    FRAME_MASK,
    FRAMES,
    PRECISION_MASK,
    PRECISIONS,
    PVT_STRUCT,
    SPEC_BY_BASE,
    TYPE_MASK,
    GnssPvt,
    MTData2Message,
    UtcTime,
    decode_satinfo,
    item_size,
    item_spans,
    payload_well_formed,
)
from .orientation import euler_from_matrix, euler_from_quaternion
from .timebase import TICKS_PER_SECOND, SampleTimeUnwrapper

_STRUCT_TO_DTYPE = {"B": "u1", "H": ">u2", "I": ">u4", "i": ">i4", "h": ">i2"}
UTC_DTYPE = np.dtype(
    [("ns", ">u4"), ("year", ">u2"), ("month", "u1"), ("day", "u1"), ("hour", "u1"), ("minute", "u1"),
     ("second", "u1"), ("flags", "u1")]
)  # fmt: skip
RAW_IMU_DTYPE = np.dtype([("counts", ">u2", (9,)), ("temp", ">i2")])
FP1632_DTYPE = np.dtype([("fraction", ">u4"), ("integer", ">i2")])
MTDATA2 = int(MID.MTDATA2)  # a plain int: enum attribute access is slow in a per-chunk path
MTDATA = int(MID.MTDATA)
#: Orientation outputs, in the order a sample takes its roll, pitch and yaw from them.
ORIENTATION_COLUMNS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "EulerAngles": np.deg2rad,
    "Quaternion": euler_from_quaternion,
    "RotationMatrix": euler_from_matrix,
}
#: Channels that make a message a sample (GNSS-only messages are not).
INERTIAL_OUTPUTS = (*ORIENTATION_COLUMNS, "RateOfTurn", "Acceleration")
#: Below this many bytes a running sum is the cheaper checksum; above, row sums per frame length.
RUNNING_SUM_LIMIT = 1 << 18
#: Up to this many rows a layout is matched with one gather; beyond, one compare per header field.
FEW_ROWS = 4096
#: Up to this many payload bytes, payload rows are gathered with an index matrix.
SMALL_GATHER = 1 << 16
#: Rows of a regular run checked before the whole buffer is (a mixed stream breaks off early).
PROBE_ROWS = 64


def _struct_dtype(fmt: str, names: Sequence[str]) -> np.dtype:
    """The numpy dtype of a big-endian ``struct`` format such as '>IH6B' with the given field names."""
    codes: list[str] = []
    digits = ""
    for char in fmt.lstrip("<>!="):
        if char.isdigit():
            digits += char
        else:
            codes += [char] * int(digits or 1)
            digits = ""
    return np.dtype([(name, _STRUCT_TO_DTYPE[code]) for name, code in zip(names, codes, strict=True)])


PVT_DTYPE = _struct_dtype(PVT_STRUCT.format, list(GnssPvt.__dataclass_fields__))


# ----------------------------------------------------------------------------------- 1+2: framing


@dataclass
class FrameScan:
    """Accepted frames of a buffer and what the sequential framer would have counted."""

    starts: np.ndarray  # preamble positions
    payload_starts: np.ndarray
    lengths: np.ndarray  # data bytes
    bad_checksums: int
    skipped_bytes: int
    consumed: int  # bytes before the first incomplete (or unconfirmed) frame: the rest waits for more data
    false_syncs: int = 0
    sync: bytes | None = b""  # the framer's sync state at ``consumed`` (``StreamFramer.sync``)
    regular_rows: np.ndarray | None = None  # (frames, frame bytes) view when all frames are one regular run


def scan_frames(
    buf: np.ndarray,
    max_length: int = MAX_DATA_LENGTH,
    sync: bytes | None = b"",
    final: bool = False,
    layouts: LayoutCache | None = None,
    ended: bool = False,
) -> FrameScan:
    """All frames ``StreamFramer`` would accept from ``buf`` (uint8), found with array operations.

    ``sync``: the framer's state at byte 0 (``StreamFramer.sync``); ``final``: the line went
    quiet (``StreamFramer.flush``); ``ended``: no more bytes will come, incomplete candidates are
    skipped (``StreamFramer.finish``; implies ``final``); ``layouts``: item layouts known to be
    well formed.
    """
    layouts = LayoutCache() if layouts is None else layouts
    final = final or ended
    count, total, header_size = _regular_run(buf, max_length, sync)
    if not count:
        return _scan_general(buf, max_length, sync, final, layouts, ended)
    rows_header = buf[:header_size].tobytes()
    rest = buf[count * total :]
    follows = _next_frame_starts(rest, int(buf[1]), int(buf[2]))
    if follows is None and final:
        follows = True
    if follows is False:  # the last row is not confirmed (rare): let the general scan sort it out
        return _scan_general(buf, max_length, sync, final, layouts, ended)
    if follows is None:  # the last row waits for the byte after it
        count -= 1
        rest = buf[count * total :]
        if not count:
            return FrameScan(*_NO_FRAMES, 0, 0, 0, sync=sync)
    offset = count * total
    starts = np.arange(0, offset, total)
    lengths = np.full(count, total - header_size - 1)
    waits = follows is None or _waits_at_start(rest, max_length)  # the usual tail: the next frame's start
    if waits and not (ended and rest.size):
        return FrameScan(starts, starts + header_size, lengths, 0, 0, offset, sync=rows_header,
                         regular_rows=buf[:offset].reshape(count, total))  # fmt: skip
    tail = _scan_general(rest, max_length, rows_header, final, layouts, ended)
    return FrameScan(
        starts=np.concatenate((starts, tail.starts + offset)),
        payload_starts=np.concatenate((starts + header_size, tail.payload_starts + offset)),
        lengths=np.concatenate((lengths, tail.lengths)),
        bad_checksums=tail.bad_checksums,
        skipped_bytes=tail.skipped_bytes,
        consumed=offset + tail.consumed,
        false_syncs=tail.false_syncs,
        sync=tail.sync,
    )


_NO_FRAMES = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))


def _next_frame_starts(rest: np.ndarray, bid: int, mid: int) -> bool | None:
    """``confirm``'s successor test on the bytes after a frame (None: not decided yet)."""
    head = rest[:3].tobytes()
    if head and head[0] == PREAMBLE:
        return True
    if len(head) == 3:
        return head[1] == bid and head[2] == mid
    return None


def _regular_run(buf: np.ndarray, max_length: int, sync: bytes | None) -> tuple[int, int, int]:
    """(count, total, header size) of the valid frames that repeat back-to-back from byte 0.

    A live stream is mostly one frame shape after another: when the bytes at 0, L, 2L, ...
    are all the same header and every row checks out, each row after the first is trusted (in
    sync, same header) and confirmed by the preamble of the next, and a reshape verifies them
    in a few array operations. The first row must continue the sync state (or pass the bus-id
    test); the last row's successor is the caller's to check.
    """
    total = frame_length(buf[:6].tobytes()) if sync is not None and buf.size and buf[0] == PREAMBLE else None
    if total is None or total > buf.size:
        return 0, 0, 0
    header_size = 6 if buf[3] == EXTENDED_LENGTH else 4
    if total - header_size - 1 > max_length:
        return 0, 0, 0
    if buf[:header_size].tobytes() != sync and buf[1] not in RESYNC_BIDS:
        return 0, 0, 0
    if buf.size >= 2 * total and buf[total : total + header_size].tobytes() != buf[:header_size].tobytes():
        return 0, 0, 0  # the next frame has another shape (a mixed stream): leave it to the general scan
    rows = buf[: buf.size // total * total].reshape(-1, total)
    count = 0
    for stop in (PROBE_ROWS, rows.shape[0]):  # probe a few rows first: mixed streams break off early
        part = rows[count:stop]
        good = (part[:, 1:].sum(axis=1, dtype=np.uint8) == 0) & (
            part[:, :header_size] == rows[0, :header_size]
        ).all(axis=1)
        if not good.all():
            return count + int(np.argmin(good)), total, header_size
        count += part.shape[0]
        if count == rows.shape[0]:
            break
    return count, total, header_size


def _waits_at_start(rest: np.ndarray, max_length: int) -> bool:
    """True when ``rest`` is just the start of one frame: the framer waits there for more bytes."""
    if not rest.size:
        return True
    if rest.size > 7 + max_length or rest[0] != PREAMBLE or (rest[1:] == PREAMBLE).any():
        return False
    total = frame_length(rest[:6].tobytes())
    header_size = 6 if rest.size > 3 and rest[3] == EXTENDED_LENGTH else 4
    return total is None or (total - header_size - 1 <= max_length and total > rest.size)


@dataclass
class _Candidates:
    """Complete candidate frames of a buffer and what is known about each (see ``_scan_general``)."""

    starts: np.ndarray
    totals: np.ndarray
    header_sizes: np.ndarray
    keys: np.ndarray  # BID, MID, header size and frame length in one number: equal keys, equal headers
    checked: np.ndarray  # checksum computed
    ok: np.ndarray  # checksum holds
    follows: np.ndarray  # the next frame starts right after it (or the capture ends there)
    waits: np.ndarray  # whether the next frame starts is not decided yet
    waiting: np.ndarray  # where ``waits`` holds: all within the last bytes, so few
    bid_ok: np.ndarray  # a bus id a resync may land on
    sizes_ok: np.ndarray  # MTData2 payload sizes add up (assumed until ``verified``)
    verified: np.ndarray


def _scan_general(
    buf: np.ndarray,
    max_length: int,
    sync: bytes | None,
    final: bool,
    layouts: LayoutCache,
    ended: bool = False,
) -> FrameScan:
    """The general scan: any mix of frames, garbage, corrupted frames and false headers (``ended``: the
    incomplete candidates never complete, so none stops the scan)."""
    n = buf.size
    cand = np.flatnonzero(buf == PREAMBLE)
    last = max(n - 1, 0)
    # FA BID MID LEN of every candidate as one big-endian word, read once (clipped reads at the end
    # are caught by ``incomplete``: a complete frame has at least 5 bytes)
    words = np.ndarray((max(n - 3, 0),), dtype=">u4", buffer=buf, strides=(1,))
    head = np.zeros(cand.size, np.int64)
    if words.size:
        head = words[np.minimum(cand, words.size - 1)].astype(np.int64)
    length = head & 0xFF
    extended = length == EXTENDED_LENGTH
    if extended.any():
        at = cand[extended]
        length[extended] = buf[np.minimum(at + 4, last)].astype(np.int64) << 8 | buf[np.minimum(at + 5, last)]
    header_size = 4 + 2 * extended
    total = header_size + length + 1
    fits = length <= max_length
    incomplete = (cand + header_size > n) | (fits & (cand + total > n))
    complete = ~incomplete & fits

    complete_at = np.flatnonzero(complete)
    c_starts, c_totals = cand[complete_at], total[complete_at]
    ends = c_starts + c_totals
    c_headers = header_size[complete_at]
    ids = head[complete_at] >> 8 & 0xFFFF  # BID, MID
    bid, mid = ids >> 8, ids & 0xFF
    follows = np.zeros(ends.size, dtype=bool)  # the byte after each is a preamble: usually the next one's
    follows[:-1] = ends[:-1] == c_starts[1:]
    elsewhere = np.flatnonzero(~follows)
    follows[elsewhere] = buf[np.minimum(ends[elsewhere], last)] == PREAMBLE
    if n and buf[last] == PREAMBLE:  # the clipped reads at the end of the buffer
        follows[elsewhere] &= ends[elsewhere] < n
    waits = np.zeros(follows.size, dtype=bool)
    other = np.flatnonzero(~follows)  # few: the byte after a frame is nearly always the next preamble
    if other.size:
        after = ends[other]
        have_ids = after + 3 <= n
        repeated = have_ids & (buf[np.minimum(after + 1, last)] == bid[other])
        repeated &= buf[np.minimum(after + 2, last)] == mid[other]
        follows[other] = repeated | (~have_ids & final)
        waits[other] = ~have_ids & (not final)
    size = complete_at.size
    bid_ok = np.zeros(size, dtype=bool)
    for resync_bid in RESYNC_BIDS:
        bid_ok |= bid == resync_bid
    keys = ids << 20 | c_headers << 17 | c_totals
    no = np.zeros(size, dtype=bool)
    c = _Candidates(c_starts, c_totals, c_headers, keys, no, no.copy(), follows, waits,
                    np.flatnonzero(waits), bid_ok, np.ones(size, bool), mid != MTDATA2)  # fmt: skip

    # Checksums are needed only where the sequential framer looks: at candidates no accepted
    # frame covers. Check the most common length first (the real frames), then the candidates
    # no valid frame of that length covers (other frame shapes, gaps), follow the chain, then
    # check whatever it leaves uncovered, until nothing unchecked is left uncovered: one pass,
    # nearly always. Payload sizes are
    # verified with the chain: only for the candidates it may take as resyncs.
    if n <= RUNNING_SUM_LIMIT or not c_totals.size:
        to_check = np.arange(size)
    else:
        common = np.flatnonzero(c_totals == np.bincount(c_totals).argmax())
        c.ok[common] = _checksums_ok(buf, c_starts[common], c_totals[common])
        c.checked[common] = True
        valid = common[c.ok[common] & c.follows[common]]
        unchecked = np.flatnonzero(~c.checked)
        to_check = unchecked[~_covered(c_starts[valid], ends[valid], c_starts[unchecked])]
    while True:
        c.ok[to_check] = _checksums_ok(buf, c_starts[to_check], c_totals[to_check])
        c.checked[to_check] = True
        chosen = _follow_chain(c, sync, lambda suspects: _verify_sizes(buf, c, suspects, layouts))
        starts, chosen_ends = c_starts[chosen], c_starts[chosen] + c_totals[chosen]
        unchecked = np.flatnonzero(~c.checked)
        to_check = unchecked[~_covered(starts, chosen_ends, c_starts[unchecked])]
        if to_check.size:
            continue
        waiting = cand[incomplete]
        if ended and chosen.size:  # nothing completes them: only one after the last frame is a cut frame
            waiting = waiting[waiting >= c_starts[chosen[-1]] + c_totals[chosen[-1]]]
        consumed, suspect = _first_stop(buf, waiting, c, chosen, sync)
        if suspect < 0 or not _verify_sizes(buf, c, np.array([suspect]), layouts):
            break

    keep = starts < consumed
    chosen, starts, chosen_ends = chosen[keep], starts[keep], chosen_ends[keep]
    looked_at = c.checked.copy()  # unchecked candidates count for nothing; accepted ones are covered
    looked_at[chosen] = False
    at = np.flatnonzero(looked_at)
    looked_at[at] = ~_covered(starts, chosen_ends, c_starts[at]) & (c_starts[at] < consumed)
    if chosen.size and consumed == chosen_ends[-1]:
        last_header = buf[starts[-1] : starts[-1] + c.header_sizes[chosen[-1]]].tobytes()
        sync = last_header
    elif chosen.size or consumed:
        sync = None
    return FrameScan(
        starts=starts,
        payload_starts=starts + c.header_sizes[chosen],
        lengths=c_totals[chosen] - c.header_sizes[chosen] - 1,
        bad_checksums=int(np.count_nonzero(looked_at & c.checked & ~c.ok)),
        skipped_bytes=consumed - int(np.sum(chosen_ends - starts)),
        consumed=consumed,
        false_syncs=int(np.count_nonzero(looked_at & c.ok)),
        sync=sync,
    )


def _sync_key(sync: bytes | None) -> int:
    """The key of the header in the sync state, as ``_Candidates.keys`` (-1: none to be trusted with)."""
    total = frame_length(sync) if sync else None
    if sync is None or total is None:
        return -1
    return int.from_bytes(sync[1:3], "big") << 20 | len(sync) << 17 | total


def _accepts(c: _Candidates, k: int, previous_key: int, wait: bool) -> bool:
    """Whether in-sync candidate ``k`` (after a header with key ``previous_key``) is accepted (``wait``:
    is waited for) once its checksum holds: trusted with the previous header, or a bus id a
    resync may land on; and confirmed by a successor (or waiting for one). ``_follow_chain``
    applies the same rule to all candidates at once."""
    return bool((c.keys[k] == previous_key or c.bid_ok[k]) and (c.waits[k] if wait else c.follows[k]))


def _verify_sizes(buf: np.ndarray, c: _Candidates, suspects: np.ndarray, layouts: LayoutCache) -> bool:
    """Check the payload sizes of the MTData2 resyncs not verified yet; True if one is refused."""
    if not suspects.size:
        return False
    payload_starts = c.starts[suspects] + c.header_sizes[suspects]
    lengths = c.totals[suspects] - c.header_sizes[suspects] - 1
    c.sizes_ok[suspects] = _well_formed(buf, payload_starts, lengths, layouts)
    c.verified[suspects] = True
    return not c.sizes_ok[suspects].all()


def _well_formed(
    buf: np.ndarray, payload_starts: np.ndarray, lengths: np.ndarray, layouts: LayoutCache
) -> np.ndarray:
    """``payload_well_formed`` of many MTData2 payloads: one walk per item layout, not per payload
    (a payload with a layout already known, same length and item headers, walks the same way);
    only the item header bytes are read."""
    ok = np.zeros(lengths.size, dtype=bool)
    for length in np.flatnonzero(np.bincount(lengths)).tolist():
        members = np.flatnonzero(lengths == length)
        starts = payload_starts[members]
        known = list(layouts.by_length.get(length, []))
        left = np.arange(members.size)
        while left.size:
            if known:
                layout = known.pop(0)
            else:
                first = buf[starts[left[0]] : starts[left[0]] + length].tobytes()
                if not payload_well_formed(first):
                    left = left[1:]
                    continue
                layout = learn_layout(first)
            same = layout.matches_at(buf, starts[left])  # same length and item headers: same walk
            ok[members[left[same]]] = True
            left = left[~same]
    return ok


def _follow_chain(c: _Candidates, sync: bytes | None, verify: Callable[[np.ndarray], bool]) -> np.ndarray:
    """The candidates the sequential framer accepts.

    After an accepted frame the next one is the valid candidate starting exactly at its end if
    that is accepted in sync (``_accepts``), else the first confirmed resync after it. Where that
    is simply the next valid candidate the chain is followed in bulk; only the "breaks" are
    walked one by one. Every candidate that may be taken as a resync (the first confirmed one
    after each break, few) has its payload sizes verified (``verify``) before the walk, so the
    chain is followed once.
    """
    valid = np.flatnonzero(c.ok)
    count = valid.size
    if not count:
        return valid
    v_starts = c.starts[valid]
    v_ends = v_starts + c.totals[valid]
    # the valid candidate starting where each ends: usually simply the next one
    after = np.arange(1, count + 1)
    has_next = np.zeros(count, dtype=bool)
    has_next[:-1] = v_starts[1:] == v_ends[:-1]
    odd = np.flatnonzero(~has_next)
    after[odd] = np.searchsorted(v_starts, v_ends[odd])
    has_next[odd] = (after[odd] < count) & (v_starts[np.minimum(after[odd], count - 1)] == v_ends[odd])
    # ``_accepts`` for every candidate that has a successor, in bulk (the successor is nearly always
    # the next valid candidate: shifted arrays, read again only where it is not)
    v_keys, v_follows = c.keys[valid], c.follows[valid]
    v_strong = c.bid_ok[valid] & v_follows  # a resync may land there (payload sizes aside)
    same, next_follows, next_strong = np.zeros(count, bool), np.zeros(count, bool), np.zeros(count, bool)
    same[:-1], next_follows[:-1], next_strong[:-1] = v_keys[1:] == v_keys[:-1], v_follows[1:], v_strong[1:]
    jumps = odd[has_next[odd]]
    same[jumps] = v_keys[after[jumps]] == v_keys[jumps]
    next_follows[jumps], next_strong[jumps] = v_follows[after[jumps]], v_strong[after[jumps]]
    in_sync_next = has_next & ((same & next_follows) | next_strong)
    following = np.where(in_sync_next, after, count)
    rest = np.flatnonzero(~in_sync_next)
    starts_sync = sync is not None and v_starts[0] == 0
    first_in_sync = starts_sync and _accepts(c, int(valid[0]), _sync_key(sync), wait=False)
    resync_from = v_ends[rest]
    if not first_in_sync:  # the first resync (after byte 0 if the candidate there was met in sync, refused)
        resync_from = np.append(resync_from, 1 if starts_sync else 0)
    strong = np.flatnonzero(v_strong)  # positions in ``valid``
    strong_starts, strong_or_none = v_starts[strong], np.append(strong, count)  # ``count``: none left
    resync_next = strong_or_none[np.searchsorted(strong_starts, resync_from)]
    moved = np.arange(resync_next.size)
    while True:  # the first confirmed resync after each break, until all of them pass the sizes check
        marked = np.zeros(count + 1, dtype=bool)
        marked[resync_next[moved]] = True
        taken_as_resync = valid[np.flatnonzero(marked[:-1])]
        verify(taken_as_resync[~c.verified[taken_as_resync]])
        taken = valid[np.minimum(resync_next, count - 1)]
        moved = np.flatnonzero(~c.sizes_ok[taken] & (resync_next < count))
        if not moved.size:
            break
        refused_at = v_starts[resync_next[moved]]
        resync_next[moved] = strong_or_none[np.searchsorted(strong_starts, refused_at, "right")]
    following[rest] = resync_next[: rest.size]
    first = 0 if first_in_sync else int(resync_next[-1])
    breaks = np.flatnonzero(following != np.arange(1, count + 1))
    marks = np.zeros(count + 1, dtype=np.int64)
    k = first
    while k < count:
        at = int(np.searchsorted(breaks, k))
        if at == breaks.size:
            marks[k] += 1
            marks[count] -= 1
            break
        marks[k] += 1
        marks[breaks[at] + 1] -= 1
        k = int(following[breaks[at]])
    return valid[np.flatnonzero(np.cumsum(marks[:-1]) > 0)]


def _first_stop(
    buf: np.ndarray, waiting: np.ndarray, c: _Candidates, chosen: np.ndarray, sync: bytes | None
) -> tuple[int, int]:
    """(where the framer stops, a held resync whose payload sizes must be verified first, else -1).

    It stops at the first candidate no accepted frame covers that is incomplete, or that is
    valid and would be accepted but for the successor test, which waits for bytes to come.
    """
    starts, ends = c.starts[chosen], c.starts[chosen] + c.totals[chosen]
    free = waiting[~_covered(starts, ends, waiting)]
    stop = int(free[0]) if free.size else buf.size
    held = c.waiting[c.ok[c.waiting] & (c.starts[c.waiting] < stop)]
    for k in held[~_covered(starts, ends, c.starts[held])].tolist():
        position = int(c.starts[k])
        previous = chosen[np.flatnonzero(ends == position)]
        if previous.size or (position == 0 and sync is not None):
            before = int(c.keys[previous[0]]) if previous.size else _sync_key(sync)
            if _accepts(c, k, before, wait=True):
                return position, -1
        elif c.bid_ok[k] and c.sizes_ok[k]:
            return position, (-1 if c.verified[k] else k)
    return stop, -1


def _covered(starts: np.ndarray, ends: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """True where a position lies inside an accepted frame (a frame's own start counts as inside)."""
    idx = np.searchsorted(starts, positions, side="right") - 1
    inside = idx >= 0
    inside[inside] = ends[idx[inside]] > positions[inside]
    return inside


def _checksums_ok(buf: np.ndarray, starts: np.ndarray, totals: np.ndarray) -> np.ndarray:
    """True where the bytes after the preamble, checksum included, sum to 0 mod 256."""
    if buf.size <= RUNNING_SUM_LIMIT:
        running = np.zeros(buf.size + 1, dtype=np.uint8)  # running[k] = sum(buf[:k]) mod 256
        np.cumsum(buf, dtype=np.uint8, out=running[1:])
        return running[starts + totals] == running[starts + 1]
    # Long buffers: sum each candidate's bytes as a row, one group per candidate length.
    ok = np.zeros(starts.size, dtype=bool)
    order = np.argsort(totals, kind="stable")
    for group in np.split(order, np.flatnonzero(np.diff(totals[order])) + 1):
        if group.size:
            rows = np.lib.stride_tricks.sliding_window_view(buf, int(totals[group[0]]) - 1)[starts[group] + 1]
            ok[group] = rows.sum(axis=1, dtype=np.uint8) == 0
    return ok


# ---------------------------------------------------------------------------------- 3: MTData2 items


@dataclass(frozen=True)
class Field:
    """One known item of a layout: its column name, XDI and how its bytes become column values."""

    name: str
    xdi: int
    convert: Callable[[np.ndarray], np.ndarray]  # structured field view (rows, ...) -> column values
    column_dtype: np.dtype
    row_shape: tuple[int, ...]


@dataclass(frozen=True)
class Layout:
    """The item sequence of one MTData2 payload: a structured dtype plus the header bytes that identify it."""

    headers: np.dtype  # structured view of the item headers (xdi u16, size u8 per item)
    header_values: tuple[int, ...]  # their values in every payload of this layout, in field order
    header_offsets: np.ndarray  # the same headers as byte offsets ...
    header_bytes: np.ndarray  # ... and byte values
    dtype: np.dtype  # structured view of the known items' data
    fields: tuple[Field, ...]
    unknown: int

    def matches_at(self, buf: np.ndarray, payload_starts: np.ndarray) -> np.ndarray:
        """``matches`` for the payloads of this layout's length starting at ``payload_starts`` in ``buf``."""
        if not self.header_values:
            return np.ones(payload_starts.size, dtype=bool)
        return (buf[payload_starts[:, None] + self.header_offsets] == self.header_bytes).all(axis=1)

    def matches(self, payloads: np.ndarray) -> np.ndarray:
        """Rows of ``payloads`` (rows, length) with exactly this layout.

        Equal length and equal header bytes at this layout's header offsets mean the item
        walk of a row goes exactly the same way, so the match is exact.
        """
        if not self.header_values:
            return np.ones(payloads.shape[0], dtype=bool)
        if payloads.shape[0] <= FEW_ROWS:  # one gather beats a compare per header field
            return (payloads[:, self.header_offsets] == self.header_bytes).all(axis=1)
        view = payloads.view(self.headers)[:, 0]
        hit = np.ones(payloads.shape[0], dtype=bool)
        for name, value in zip(self.headers.names or (), self.header_values, strict=True):
            hit &= view[name] == value
        return hit


def _item_field(xdi: int, size: int) -> tuple[np.dtype, Field] | None:
    """(field dtype, Field) of a known item; None for unknown XDIs; ProtocolError for impossible sizes."""
    spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
    if spec is None:
        return None
    expected = item_size(spec, xdi)
    if expected is not None and size != expected:
        raise ProtocolError(f"0x{xdi:04X} needs {expected} data bytes, a message gives {size}")
    if spec.kind == "real":
        precision = xdi & PRECISION_MASK
        shape = () if spec.count == 1 else (spec.count,)
        if precision == PRECISIONS["fp1632"]:
            dtype = np.dtype((FP1632_DTYPE, shape))
            convert = _fp1632
        else:
            dtype = np.dtype(({0: ">f4", 1: ">i4", 3: ">f8"}[precision], shape))
            convert = _fp1220 if precision == PRECISIONS["fp1220"] else _to_float
        return dtype, Field(spec.name, xdi, convert, np.dtype(np.float64), shape)
    if spec.kind == "int":
        return np.dtype(_STRUCT_TO_DTYPE[spec.fmt[-1]]), Field(
            spec.name, xdi, _to_int, np.dtype(np.int64), ()
        )
    if spec.kind == "deviceid":
        if size not in (4, 8):
            raise ProtocolError(f"DeviceId needs 4 or 8 data bytes, a message gives {size}")
        return np.dtype(">u4" if size == 4 else ">u8"), Field(
            spec.name, xdi, _to_uint, np.dtype(np.uint64), ()
        )
    if spec.kind == "satinfo":
        decode_satinfo(bytes(size))  # raises for a size that is not 8 + 4 per satellite
        return np.dtype(("u1", (size,))), Field(spec.name, xdi, _satinfo, np.dtype(object), ())
    structured = {"utc": UTC_DTYPE, "pvt": PVT_DTYPE, "ints": RAW_IMU_DTYPE}[spec.kind]
    return structured, Field(spec.name, xdi, np.copy, structured, ())


def _to_float(view: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):  # a signalling NaN in the bytes is a NaN, not a warning
        return view.astype(np.float64)


def _to_int(view: np.ndarray) -> np.ndarray:
    return view.astype(np.int64)


def _to_uint(view: np.ndarray) -> np.ndarray:
    return view.astype(np.uint64)


def _fp1220(view: np.ndarray) -> np.ndarray:
    return view.astype(np.float64) / FP1220_SCALE


def _fp1632(view: np.ndarray) -> np.ndarray:
    raw = (view["integer"].astype(np.int64) << 32) + view["fraction"]
    return raw.astype(np.float64) / FP1632_SCALE  # |raw| < 2**47: exact in float64


def _satinfo(view: np.ndarray) -> np.ndarray:
    out = np.empty(view.shape[0], dtype=object)
    out[:] = [decode_satinfo(row.tobytes()) for row in view]
    return out


def learn_layout(payload: bytes) -> Layout:
    """The layout of one MTData2 payload; ProtocolError if its sizes do not add up or cannot be."""
    spans = item_spans(payload)
    names: list[str] = []
    formats: list[np.dtype] = []
    offsets: list[int] = []
    fields: list[Field] = []
    unknown = 0
    for xdi, offset, size in spans:
        found = _item_field(xdi, size)
        if found is None:
            unknown += 1
            continue
        dtype, item = found
        if item.name in names:  # a repeated output: the last one wins, as in decode_mtdata2
            drop = names.index(item.name)
            for seq in (names, formats, offsets, fields):
                del seq[drop]
        names.append(item.name)
        formats.append(dtype)
        offsets.append(offset)
        fields.append(item)
    itemsize = max(len(payload), 1)  # empty payloads get a one-byte placeholder record
    headers = np.dtype(
        {
            "names": [f"{kind}{j}" for j in range(len(spans)) for kind in ("xdi", "size")],
            "formats": ["u1" if kind else ">u2" for _ in spans for kind in (0, 1)],
            "offsets": [offset - shift for _, offset, _ in spans for shift in (3, 1)],
            "itemsize": itemsize,
        }
    )
    header_offsets = np.array([offset - back for _, offset, _ in spans for back in (3, 2, 1)], dtype=np.int64)
    return Layout(
        headers=headers,
        header_values=tuple(value for xdi, _, size in spans for value in (xdi, size)),
        header_offsets=header_offsets,
        header_bytes=np.frombuffer(payload, dtype=np.uint8)[header_offsets],
        dtype=np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize}),
        fields=tuple(fields),
        unknown=unknown,
    )


class LayoutCache:
    """Layouts seen so far, by payload length, so a stream learns each layout once.

    At most ``per_length`` layouts are kept per length, most recently used first, so a noisy
    stream with many one-off layouts cannot make every later match slower.
    """

    def __init__(self, per_length: int = 16) -> None:
        self.per_length = per_length
        self.by_length: dict[int, list[Layout]] = {}

    def assign(self, payloads: np.ndarray) -> tuple[list[tuple[Layout, np.ndarray]], np.ndarray]:
        """Split equal-length payload rows by layout: ([(layout, rows)], malformed rows)."""
        known = self.by_length.get(payloads.shape[1], [])
        unassigned = np.arange(payloads.shape[0])
        groups: list[tuple[Layout, np.ndarray]] = []
        malformed: list[int] = []
        for layout in known:
            if not unassigned.size:
                break
            unassigned = _take(layout, payloads, unassigned, groups)
        while unassigned.size:
            try:
                layout = learn_layout(payloads[unassigned[0]].tobytes())
            except ProtocolError:
                malformed.append(int(unassigned[0]))
                unassigned = unassigned[1:]
                continue
            unassigned = _take(layout, payloads, unassigned, groups)
        used = [layout for layout, _ in groups]
        self.by_length[payloads.shape[1]] = (used + [k for k in known if k not in used])[: self.per_length]
        return groups, np.array(malformed, dtype=np.int64)


def _take(
    layout: Layout, payloads: np.ndarray, unassigned: np.ndarray, groups: list[tuple[Layout, np.ndarray]]
) -> np.ndarray:
    """Add (layout, its rows among ``unassigned``) to ``groups`` if any match; return the rows left."""
    rows = payloads if unassigned.size == payloads.shape[0] else payloads[unassigned]
    hit = layout.matches(rows)
    if not hit.any():
        return unassigned
    groups.append((layout, unassigned[hit]))
    return unassigned[~hit]


# -------------------------------------------------------------------------------------- the block


@dataclass
class DecodedBlock:
    """Columnar decode of a run of frames.

    ``columns[name]`` has one row per accepted MTData2 message (NaN / 0 / None where the
    message lacks the output, see ``present[name]``), ``xdis[name]`` the identifier each row
    came with. ``frame_index`` places each message among all frames; ``other_frames`` are
    the remaining frames (acks, errors, legacy MTData) at ``other_index``.
    """

    n_messages: int = 0
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    present: dict[str, np.ndarray] = field(default_factory=dict)
    xdis: dict[str, np.ndarray] = field(default_factory=dict)
    unknown_counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    frame_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    other_frames: list[Frame] = field(default_factory=list)
    other_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    frames: int = 0
    bad_checksums: int = 0
    skipped_bytes: int = 0
    malformed: int = 0  # MTData2 frames whose item sizes do not add up (rejected)
    false_syncs: int = 0  # checksum-valid candidates the framer could not confirm
    pending_bytes: int = 0  # trailing bytes that may start a frame still incomplete (or unconfirmed)
    carried: int = 0  # data messages (MTData2, legacy MTData) whose bytes began before this block's input
    sync: bytes | None = b""  # the framer's sync state where the pending bytes start

    @property
    def unknown_ids(self) -> int:
        """Items skipped because their identifier is unknown."""
        return int(self.unknown_counts.sum())

    def message(self, index: int) -> MTData2Message:
        """Row ``index`` as the per-message decoder returns it (unknown items are counted, not named)."""
        return next(self.messages(index, index + 1))

    def messages(self, start: int = 0, stop: int | None = None) -> Iterator[MTData2Message]:
        """Rows ``start:stop`` as per-message values; columns are converted to Python once, not per cell."""
        rows = slice(start, self.n_messages if stop is None else stop)
        names = [name for name in self.columns if self.present[name][rows].any()]
        values = {name: _python_column(name, self.columns[name][rows]) for name in names}
        present = {name: self.present[name][rows].tolist() for name in names}
        xdis = {name: self.xdis[name][rows].tolist() for name in names}
        for row, unknown in enumerate(self.unknown_counts[rows].tolist()):
            here = [name for name in names if present[name][row]]
            yield MTData2Message(
                {name: values[name][row] for name in here},
                {name: xdis[name][row] for name in here},
                (0,) * unknown,
            )

    @staticmethod
    def concat(blocks: Sequence[DecodedBlock]) -> DecodedBlock:
        """One block from consecutive blocks (a column missing from some blocks is absent there)."""
        out = DecodedBlock()
        examples: dict[str, np.ndarray] = {}
        for block in blocks:
            for name, column in block.columns.items():
                examples.setdefault(name, column)
        for name, example in examples.items():
            out.columns[name] = np.concatenate(
                [b.columns[name] if name in b.columns else _absent(example, b.n_messages) for b in blocks]
            )
            out.present[name] = np.concatenate(
                [b.present.get(name, np.zeros(b.n_messages, bool)) for b in blocks]
            )
            out.xdis[name] = np.concatenate(
                [b.xdis.get(name, np.zeros(b.n_messages, np.int64)) for b in blocks]
            )
        offsets = np.cumsum([0, *(b.frames for b in blocks)])
        out.frame_index = np.concatenate(
            [out.frame_index, *(b.frame_index + o for b, o in zip(blocks, offsets[:-1], strict=True))]
        )
        out.other_index = np.concatenate(
            [out.other_index, *(b.other_index + o for b, o in zip(blocks, offsets[:-1], strict=True))]
        )
        out.unknown_counts = np.concatenate([out.unknown_counts, *(b.unknown_counts for b in blocks)])
        for block in blocks:
            out.other_frames += block.other_frames
        for counter in ("n_messages", "frames", "bad_checksums", "skipped_bytes", "malformed", "false_syncs"):
            setattr(out, counter, sum(getattr(b, counter) for b in blocks))
        out.pending_bytes = blocks[-1].pending_bytes if blocks else 0
        out.sync = blocks[-1].sync if blocks else b""
        return out


def _absent(example: np.ndarray, rows: int) -> np.ndarray:
    """A column of ``rows`` absent values shaped like ``example`` (NaN for reals)."""
    out = np.zeros((rows, *example.shape[1:]), dtype=example.dtype)
    if out.dtype == np.float64:
        out.fill(np.nan)
    return out


def _python_column(name: str, column: np.ndarray) -> list[object]:
    """A column as the per-message decoder's Python values (tuples for vectors, dataclasses for records)."""
    if column.dtype == object:
        return list(column)
    records = column.tolist()
    if column.dtype.names is None:
        return [tuple(row) for row in records] if column.ndim > 1 else records
    if name == "UtcTime":
        return [UtcTime(*record) for record in records]
    if name == "GnssPvtData":
        return [GnssPvt(*record) for record in records]
    return [(*counts.tolist(), temp) for counts, temp in records]  # RawAccGyrMagTemp


def decode_buffer(
    buf: np.ndarray,
    max_length: int = MAX_DATA_LENGTH,
    layouts: LayoutCache | None = None,
    *,
    sync: bytes | None = b"",
    final: bool = False,
    carried_below: int = 0,
    ended: bool = False,
) -> DecodedBlock:
    """Decode every complete frame of ``buf`` (uint8); bytes from ``consumed`` on are left pending.

    ``sync``, ``final`` and ``ended`` as in ``scan_frames``; ``carried_below``: bytes of ``buf`` held
    over from earlier input (the data messages starting there are counted in ``carried``).
    """
    layouts = LayoutCache() if layouts is None else layouts
    scan = scan_frames(buf, max_length, sync, final, layouts, ended)
    held_over = scan.starts[: int(np.searchsorted(scan.starts, carried_below))].tolist()  # 0, 1 or 2 frames
    block = DecodedBlock(
        carried=sum(int(buf[start + 2]) in (MTDATA2, MTDATA) for start in held_over),
        frames=int(scan.starts.size),
        bad_checksums=scan.bad_checksums,
        skipped_bytes=scan.skipped_bytes,
        false_syncs=scan.false_syncs,
        pending_bytes=buf.size - scan.consumed,
        sync=scan.sync,
    )
    if scan.regular_rows is not None and scan.regular_rows[0, 2] == MTDATA2:  # one frame shape throughout
        header_size = int(scan.payload_starts[0])
        data_frames = np.arange(scan.starts.size)
        payloads = scan.regular_rows[:, header_size:-1]
        groups, malformed = _assign_layouts(payloads, data_frames, layouts)
    else:
        is_data = buf[scan.starts + 2] == MTDATA2
        if not is_data.all():
            others = np.flatnonzero(~is_data)
            block.other_index = others
            block.other_frames = [
                Frame(int(buf[s + 1]), int(buf[s + 2]), buf[p : p + n].tobytes())
                for s, p, n in zip(
                    scan.starts[others].tolist(),
                    scan.payload_starts[others].tolist(),
                    scan.lengths[others].tolist(),
                    strict=True,
                )
            ]
        data_frames = np.flatnonzero(is_data)
        groups, malformed = _layout_groups(
            buf, scan.payload_starts[data_frames], scan.lengths[data_frames], layouts
        )
    _fill_columns(block, data_frames, groups, malformed)
    return block


def _fill_columns(
    block: DecodedBlock,
    data_frames: np.ndarray,
    groups: list[tuple[Layout, np.ndarray, np.ndarray]],
    malformed: np.ndarray,
) -> None:
    """Columns, presence and identifiers of the accepted MTData2 messages, in stream order."""
    block.malformed = int(malformed.size)
    block.n_messages = data_frames.size - block.malformed
    if len(groups) == 1 and not malformed.size:  # the common case: one layout, every row present
        layout, _, records = groups[0]
        block.frame_index = data_frames
        block.unknown_counts = np.full(block.n_messages, layout.unknown, dtype=np.int64)
        everywhere = np.ones(block.n_messages, dtype=bool)
        everywhere.flags.writeable = False  # shared by all columns
        for item in layout.fields:
            block.columns[item.name] = item.convert(records[item.name])
            block.present[item.name] = everywhere
            block.xdis[item.name] = np.full(block.n_messages, item.xdi, dtype=np.int64)
        return
    accepted = np.ones(data_frames.size, dtype=bool)
    accepted[malformed] = False
    block.frame_index = data_frames[accepted]
    row_of = np.cumsum(accepted) - 1
    block.unknown_counts = np.zeros(block.n_messages, dtype=np.int64)
    for layout, members, records in groups:
        rows = row_of[members]
        block.unknown_counts[rows] = layout.unknown
        for item in layout.fields:
            if item.name not in block.columns:
                block.columns[item.name] = _absent(
                    np.zeros((0, *item.row_shape), item.column_dtype), block.n_messages
                )
                block.present[item.name] = np.zeros(block.n_messages, dtype=bool)
                block.xdis[item.name] = np.zeros(block.n_messages, dtype=np.int64)
            block.columns[item.name][rows] = item.convert(records[item.name])
            block.present[item.name][rows] = True
            block.xdis[item.name][rows] = item.xdi


def _layout_groups(
    buf: np.ndarray, payload_starts: np.ndarray, lengths: np.ndarray, layouts: LayoutCache
) -> tuple[list[tuple[Layout, np.ndarray, np.ndarray]], np.ndarray]:
    """(layout, frame indices, structured records) per layout, and the malformed frame indices."""
    if lengths.size == 0:
        return [], np.empty(0, dtype=np.int64)
    if lengths[0] == lengths[-1] and (lengths == lengths[0]).all():
        by_length = [np.arange(lengths.size)]
    else:
        order = np.argsort(lengths, kind="stable")
        by_length = np.split(order, np.flatnonzero(np.diff(lengths[order])) + 1)
    groups: list[tuple[Layout, np.ndarray, np.ndarray]] = []
    malformed: list[np.ndarray] = []
    for frames in by_length:
        payloads = _payload_rows(buf, payload_starts[frames], int(lengths[frames[0]]))
        assigned, bad = _assign_layouts(payloads, frames, layouts)
        groups += assigned
        malformed.append(bad)
    return groups, np.sort(np.concatenate(malformed))


def _assign_layouts(
    payloads: np.ndarray, frames: np.ndarray, layouts: LayoutCache
) -> tuple[list[tuple[Layout, np.ndarray, np.ndarray]], np.ndarray]:
    """Equal-length payload rows of ``frames`` split by layout, each as structured records."""
    assigned, bad = layouts.assign(payloads)
    groups = []
    for layout, rows in assigned:
        if not payloads.shape[1]:  # empty payloads: the layout's dtype is a one-byte placeholder
            records = np.zeros((rows.size, 1), dtype=np.uint8)
        else:
            records = payloads if rows.size == frames.size else payloads[rows]
        groups.append((layout, frames[rows], records.view(layout.dtype)[:, 0]))
    return groups, frames[bad]


def _payload_rows(buf: np.ndarray, starts: np.ndarray, length: int) -> np.ndarray:
    """(frames, length) payload bytes: a gather when small, a strided view when evenly spaced."""
    if not length:
        return np.zeros((starts.size, 0), dtype=np.uint8)
    if starts.size * length <= SMALL_GATHER:  # an index matrix is cheaper than building a window view
        return buf[starts[:, None] + np.arange(length)]
    step = int(starts[1] - starts[0])
    if (
        step >= length
        and starts[-1] - starts[0] == step * (starts.size - 1)
        and (np.diff(starts) == step).all()
    ):
        return np.lib.stride_tricks.as_strided(
            buf[starts[0] :], (starts.size, length), (step, 1), writeable=False
        )
    return np.lib.stride_tricks.sliding_window_view(buf, length)[starts]


def decode_capture(data: bytes, max_length: int = MAX_DATA_LENGTH) -> DecodedBlock:
    """Batch-decode a whole raw capture (bytes as read from the serial port; nothing follows them)."""
    return decode_buffer(np.frombuffer(data, dtype=np.uint8), max_length, ended=True)


# ----------------------------------------------------------------------------------- to samples


def to_samples(
    block: DecodedBlock, unwrapper: SampleTimeUnwrapper, host_t: float | np.ndarray | None = None
) -> np.ndarray:
    """``SAMPLE_DTYPE`` rows for the inertial messages of a block (Euler deg -> rad, time from ticks).

    GNSS-only messages are not samples; messages without SampleTimeFine cannot be placed in
    time and are dropped, and so are messages whose SampleTimeFine is beyond the device clock's
    range or whose orientation (Euler angles, quaternion or rotation matrix: the first the device
    gives, ``xsens.orientation``) is not ENU (the driver configured ENU): a corrupted frame passes
    the one-byte checksum once in 256, and one such frame must never stop a recording. Its
    PacketCounter is then missing, so it shows as a lost packet. Never raises on bytes.
    ``unwrapper`` carries the time base across consecutive blocks.
    """
    none = np.zeros(block.n_messages, dtype=bool)
    inertial = none.copy()
    for name in INERTIAL_OUTPUTS:
        inertial |= block.present.get(name, none)
    rows = np.flatnonzero(inertial & block.present.get("SampleTimeFine", none))
    if rows.size:
        rows = rows[block.columns["SampleTimeFine"][rows].astype(np.int64) < unwrapper.modulus]
    for name in ORIENTATION_COLUMNS:
        if name in block.xdis and rows.size:
            given = block.present[name][rows]
            rows = rows[~(given & (block.xdis[name][rows] & FRAME_MASK != FRAMES["ENU"]))]
    out = empty_samples(rows.size)
    if not rows.size:
        return out
    out["ticks"] = unwrapper.update_many(block.columns["SampleTimeFine"][rows])
    out["t"] = out["ticks"] / TICKS_PER_SECOND
    if host_t is not None:
        out["host_t"] = host_t
    for name, to_rad in reversed(ORIENTATION_COLUMNS.items()):  # Euler angles win where several came
        if name in block.columns:
            given = block.present[name][rows]
            every = bool(given.all())
            angles = to_rad(block.columns[name][rows] if every else block.columns[name][rows][given])
            for axis, sample_field in enumerate(("roll", "pitch", "yaw")):
                if every:
                    out[sample_field] = angles[:, axis]
                else:
                    out[sample_field][given] = angles[:, axis]
    for name, sample_fields in {"RateOfTurn": ("p", "q", "r"), "Acceleration": ("ax", "ay", "az")}.items():
        if name in block.columns:
            values = block.columns[name][rows]
            for axis, sample_field in enumerate(sample_fields):
                out[sample_field] = values[:, axis]
    if "PacketCounter" in block.columns:
        out["counter"] = block.columns["PacketCounter"][rows]
    for status in ("StatusByte", "StatusWord"):  # StatusWord wins where both exist
        if status in block.columns:
            present = block.present[status][rows]
            out["status"][present] = block.columns[status][rows][present]
    return out
