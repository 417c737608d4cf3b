"""Vectorised decoding of raw Xbus captures into columns (numpy), with the framer's exact semantics.

``frame_scan`` finds the frames the sequential framer accepts; MTData2 frames are then grouped
by item layout (``layouts``: one structured dtype per layout, so all its fields are read with
one gather and big-endian views) and assembled here into a ``DecodedBlock``: per output name
an array (one row per MTData2 message) and a presence mask, the counters, and the non-MTData2
frames (acks, errors) as ``Frame`` objects. ``to_samples`` turns a block into sample rows.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..samples import empty_samples
from .constants import MAX_DATA_LENGTH, MID
from .frame import Frame
from .frame_scan import MTDATA2, scan_frames
from .framer import RESYNC_BIDS
from .layouts import Layout, LayoutCache
from .mtdata2 import FRAME_MASK, FRAMES, GnssPvt, MTData2Message, UtcTime
from .orientation import euler_from_matrix, euler_from_quaternion
from .timebase import TICKS_PER_SECOND, SampleTimeUnwrapper

MTDATA = int(MID.MTDATA)  # a plain int: enum attribute access is slow in a per-chunk path
#: Orientation outputs, in the order a sample takes its roll, pitch and yaw from them.
ORIENTATION_COLUMNS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "EulerAngles": np.deg2rad,
    "Quaternion": euler_from_quaternion,
    "RotationMatrix": euler_from_matrix,
}
#: Channels that make a message a sample (GNSS-only messages are not).
INERTIAL_OUTPUTS = (*ORIENTATION_COLUMNS, "RateOfTurn", "Acceleration")
#: Up to this many payload bytes, payload rows are gathered with an index matrix.
SMALL_GATHER = 1 << 16


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
    bus_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.uint8))  # each message's
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
        out.bus_ids = np.concatenate([out.bus_ids, *(b.bus_ids for b in blocks)])
        for block in blocks:
            out.other_frames += block.other_frames
        for counter in ("n_messages", "frames", "bad_checksums", "skipped_bytes", "malformed", "false_syncs"):
            setattr(out, counter, sum(getattr(b, counter) for b in blocks))
        out.pending_bytes = blocks[-1].pending_bytes if blocks else 0
        out.sync = blocks[-1].sync if blocks else b""
        return out

    def take(self, rows: np.ndarray) -> DecodedBlock:
        """The messages at ``rows`` (one device's of a log), with their columns; frames and counters stay
        the whole block's."""
        out = DecodedBlock(rows.size, frame_index=self.frame_index[rows], bus_ids=self.bus_ids[rows])
        out.unknown_counts = self.unknown_counts[rows]
        for name, column in self.columns.items():
            out.columns[name] = column[rows]
            out.present[name] = self.present[name][rows]
            out.xdis[name] = self.xdis[name][rows]
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
    bids: frozenset[int] = RESYNC_BIDS,
) -> DecodedBlock:
    """Decode every complete frame of ``buf`` (uint8); bytes from ``consumed`` on are left pending.

    ``sync``, ``final`` and ``ended`` as in ``scan_frames``; ``carried_below``: bytes of ``buf`` held
    over from earlier input (the data messages starting there are counted in ``carried``); ``bids``: the
    bus ids a resync may land on (``framer.ANY_BID``: a log of several devices).
    """
    layouts = LayoutCache() if layouts is None else layouts
    scan = scan_frames(buf, max_length, sync, final, layouts, ended, bids)
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
    block.bus_ids = buf[scan.starts[block.frame_index] + 1]
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


def decode_capture(
    data: bytes, max_length: int = MAX_DATA_LENGTH, bids: frozenset[int] = RESYNC_BIDS
) -> DecodedBlock:
    """Batch-decode a whole raw capture (bytes as read from the serial port; nothing follows them)."""
    return decode_buffer(np.frombuffer(data, dtype=np.uint8), max_length, ended=True, bids=bids)


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
