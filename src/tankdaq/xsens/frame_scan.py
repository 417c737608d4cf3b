"""Vectorised frame scanning of raw Xbus bytes, with ``StreamFramer``'s exact semantics.

A per-message Python framer manages ~1e5 frames/s; a long capture needs array code:

1. every 0xFA is a candidate frame start; lengths and checksums are checked for all
   candidates at once (row sums of equal-length candidates, or a mod-256 running sum);
2. the frames the sequential framer accepts (the first valid frame at or after the end of
   the previous one) are chosen by following a ``next`` pointer, in bulk over the runs where
   the next frame is simply the next valid candidate.

The result is a ``FrameScan`` (frame positions and the framer's counters); turning the
MTData2 payloads into columns is ``xsens.column_decoder``'s job.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .constants import EXTENDED_LENGTH, MAX_DATA_LENGTH, MID, PREAMBLE
from .frame import frame_length
from .framer import RESYNC_BIDS
from .layouts import LayoutCache, learn_layout
from .mtdata2 import payload_well_formed

MTDATA2 = int(MID.MTDATA2)  # a plain int: enum attribute access is slow in a per-chunk path
#: Below this many bytes a running sum is the cheaper checksum; above, row sums per frame length.
RUNNING_SUM_LIMIT = 1 << 18
#: Rows of a regular run checked before the whole buffer is (a mixed stream breaks off early).
PROBE_ROWS = 64


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
    bids: frozenset[int] = RESYNC_BIDS,
) -> FrameScan:
    """All frames ``StreamFramer`` would accept from ``buf`` (uint8), found with array operations.

    ``sync``: the framer's state at byte 0 (``StreamFramer.sync``); ``final``: the line went
    quiet (``StreamFramer.flush``); ``ended``: no more bytes will come, incomplete candidates are
    skipped (``StreamFramer.finish``; implies ``final``); ``layouts``: item layouts known to be
    well formed; ``bids``: the bus ids a resync may land on (``framer.ANY_BID`` for a log).
    """
    layouts = LayoutCache() if layouts is None else layouts
    final = final or ended
    count, total, header_size = _regular_run(buf, max_length, sync, bids)
    if not count:
        return _scan_general(buf, max_length, sync, final, layouts, ended, bids)
    rows_header = buf[:header_size].tobytes()
    rest = buf[count * total :]
    follows = _next_frame_starts(rest, int(buf[1]), int(buf[2]))
    if follows is None and final:
        follows = True
    if follows is False:  # the last row is not confirmed (rare): let the general scan sort it out
        return _scan_general(buf, max_length, sync, final, layouts, ended, bids)
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
    tail = _scan_general(rest, max_length, rows_header, final, layouts, ended, bids)
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


def _regular_run(
    buf: np.ndarray, max_length: int, sync: bytes | None, bids: frozenset[int]
) -> tuple[int, int, int]:
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
    if buf[:header_size].tobytes() != sync and buf[1] not in bids:
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
    bids: frozenset[int] = RESYNC_BIDS,
) -> FrameScan:
    """The general scan: any mix of frames, garbage, corrupted frames and false headers (``ended``: the
    incomplete candidates never complete, so none stops the scan)."""
    c, incomplete_starts = _candidates(buf, max_length, final, bids)
    n, size, c_starts, c_totals = buf.size, c.starts.size, c.starts, c.totals
    ends = c_starts + c_totals

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
        waiting = incomplete_starts
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


def _candidates(
    buf: np.ndarray, max_length: int, final: bool, bids: frozenset[int]
) -> tuple[_Candidates, np.ndarray]:
    """(the complete candidate frames of ``buf``, the starts of the incomplete ones): every preamble
    read as a header, with the successor test done in bulk (``final``: the line went quiet, so a
    frame at the very end needs no successor)."""
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
    allowed = np.zeros(256, dtype=bool)  # a lookup: as cheap for every bus id as for two
    allowed[list(bids)] = True
    bid_ok = allowed[bid]
    keys = ids << 20 | c_headers << 17 | c_totals
    no = np.zeros(size, dtype=bool)
    c = _Candidates(c_starts, c_totals, c_headers, keys, no, no.copy(), follows, waits,
                    np.flatnonzero(waits), bid_ok, np.ones(size, bool), mid != MTDATA2)  # fmt: skip
    return c, cand[incomplete]


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
