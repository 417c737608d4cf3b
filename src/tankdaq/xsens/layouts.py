"""Item layouts of MTData2 payloads as numpy structured dtypes, so equal payloads decode in one gather.

A layout is learnt from one payload; every payload of the same length whose item headers sit
at the same offsets with the same bytes has, by construction, the same item walk, so all its
fields are read with one big-endian structured view. Kept apart from the frame scanner (which
only asks whether payload sizes add up) and from the column assembly (which only converts).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import ProtocolError
from .constants import DataKind
from .mtdata2 import (
    FP1220_SCALE,
    FP1632_SCALE,
    PRECISION_MASK,
    PRECISIONS,
    PVT_STRUCT,
    SPEC_BY_BASE,
    TYPE_MASK,
    GnssPvt,
    decode_satinfo,
    item_size,
    item_spans,
)

_STRUCT_TO_DTYPE = {"B": "u1", "H": ">u2", "I": ">u4", "i": ">i4", "h": ">i2"}
UTC_DTYPE = np.dtype(
    [("ns", ">u4"), ("year", ">u2"), ("month", "u1"), ("day", "u1"), ("hour", "u1"), ("minute", "u1"),
     ("second", "u1"), ("flags", "u1")]
)  # fmt: skip
RAW_IMU_DTYPE = np.dtype([("counts", ">u2", (9,)), ("temp", ">i2")])
FP1632_DTYPE = np.dtype([("fraction", ">u4"), ("integer", ">i2")])
#: Up to this many rows a layout is matched with one gather; beyond, one compare per header field.
FEW_ROWS = 4096


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
    if spec.kind == DataKind.REAL:
        precision = xdi & PRECISION_MASK
        shape = () if spec.count == 1 else (spec.count,)
        if precision == PRECISIONS["fp1632"]:
            dtype = np.dtype((FP1632_DTYPE, shape))
            convert = _fp1632
        else:
            dtype = np.dtype(({0: ">f4", 1: ">i4", 3: ">f8"}[precision], shape))
            convert = _fp1220 if precision == PRECISIONS["fp1220"] else _to_float
        return dtype, Field(spec.name, xdi, convert, np.dtype(np.float64), shape)
    if spec.kind == DataKind.INT:
        return np.dtype(_STRUCT_TO_DTYPE[spec.fmt[-1]]), Field(
            spec.name, xdi, _to_int, np.dtype(np.int64), ()
        )
    if spec.kind == DataKind.DEVICEID:
        if size not in (4, 8):
            raise ProtocolError(f"DeviceId needs 4 or 8 data bytes, a message gives {size}")
        return np.dtype(">u4" if size == 4 else ">u8"), Field(
            spec.name, xdi, _to_uint, np.dtype(np.uint64), ()
        )
    if spec.kind == DataKind.SATINFO:
        decode_satinfo(bytes(size))  # raises for a size that is not 8 + 4 per satellite
        return np.dtype(("u1", (size,))), Field(spec.name, xdi, _satinfo, np.dtype(object), ())
    structured = {DataKind.UTC: UTC_DTYPE, DataKind.PVT: PVT_DTYPE, DataKind.INTS: RAW_IMU_DTYPE}[spec.kind]
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
