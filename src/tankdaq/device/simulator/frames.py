"""The simulated MTi's MTData2 frames of a block of samples, made at once with numpy.

Frame by frame through ``encode_mtdata2`` and ``build_frame``, a 100 Hz stream cost the simulator
~120 µs of Python per frame. The frames of a block differ only in their values and in which of the
slower outputs they carry (a 100 Hz output at 400 Hz rides along every fourth frame), so the rows that
carry the same outputs share one layout: a template of the whole frame (header, item headers) into which
numpy writes every row's values at once, big-endian in the precision each XDI's low bits select, then the
checksums. The bytes are ``build_frame(MID.MTDATA2, encode_mtdata2(items))``'s for every row
(tests/device/test_simulator_frames.py holds them to it). Values the reference refuses or packs its own
way (fixed point out of range, float32 overflow or NaN) go frame by frame through the reference encoders
instead, which raise what they raise.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...errors import ProtocolError
from ...physics.truth import TICKS_PER_S
from ...samples import SAMPLE_DTYPE
from ...xsens.constants import MID, DataKind
from ...xsens.frame import build_frame
from ...xsens.mtdata2 import (
    FP1220_SCALE,
    FP1632_SCALE,
    PRECISION_MASK,
    PRECISIONS,
    SPEC_BY_BASE,
    TYPE_MASK,
    encode_mtdata2,
    item_size,
)
from ...xsens.orientation import quaternion, rotation_matrix

#: FP16.32 on the wire: the fraction (u32) first, then the integer part (i16).
FP1632 = np.dtype([("fraction", ">u4"), ("integer", ">i2")])
#: The wire type of one real value, by the XDI's precision bits.
REAL_TYPES = {
    PRECISIONS["float32"]: np.dtype(">f4"),
    PRECISIONS["fp1220"]: np.dtype(">i4"),
    PRECISIONS["fp1632"]: FP1632,
    PRECISIONS["float64"]: np.dtype(">f8"),
}


def _axes() -> np.dtype:
    """The three-axis outputs as (n, 3) views of a block of samples: their fields follow each other as
    float64 in ``SAMPLE_DTYPE`` (a view of the same bytes costs a sixth of stacking the three columns)."""
    fields = SAMPLE_DTYPE.fields
    assert fields is not None  # a structured dtype
    return np.dtype(
        {
            "names": ["EulerAngles", "RateOfTurn", "Acceleration"],
            "formats": [np.dtype((np.float64, (3,)))] * 3,
            "offsets": [fields[first][1] for first in ("roll", "p", "ax")],
            "itemsize": SAMPLE_DTYPE.itemsize,
        }
    )


AXES = _axes()


def output_values(name: str, block: np.ndarray, clock_modulus: int) -> np.ndarray:
    """Output ``name``'s values for every sample of ``block`` in device units (Euler angles in degrees, as
    on the wire): one per row, or a row of them (quaternion, matrix in wire order, three axes)."""
    match name:
        case "PacketCounter":
            return block["counter"]
        case "SampleTimeFine":
            return block["ticks"] % clock_modulus
        case "SampleTimeCoarse":
            return (block["ticks"] // TICKS_PER_S) & 0xFFFFFFFF
        case "StatusWord":
            return block["status"]
        case "StatusByte":
            return block["status"] & 0xFF
        case "Quaternion":
            return quaternion(block["roll"], block["pitch"], block["yaw"])
        case "RotationMatrix":
            return rotation_matrix(block["roll"], block["pitch"], block["yaw"])
        case "EulerAngles":
            return np.degrees(block.view(AXES)[name])
        case "RateOfTurn" | "Acceleration":
            return block.view(AXES)[name]
    raise ProtocolError(f"the simulated MTi cannot send {name}")


def _on_the_wire(values: np.ndarray, xdi: int) -> np.ndarray | None:
    """``values`` as the XDI's precision puts them in a frame (numpy casts to its field's type on
    assignment); None where the reference encoder refuses a value or packs it otherwise."""
    if SPEC_BY_BASE[xdi & TYPE_MASK].kind != DataKind.REAL:
        return values  # counters, times, status: integers the sample's types hold
    bits = xdi & PRECISION_MASK
    if bits == PRECISIONS["float64"]:
        return values
    if bits == PRECISIONS["float32"]:
        with np.errstate(over="ignore"):
            single = values.astype(np.float32)
        # struct refuses what overflows to inf, and keeps a NaN's payload its own way (3.14: sNaN stays one)
        return single if np.isfinite(single).all() else None
    scale, limit = (FP1220_SCALE, 1 << 31) if bits == PRECISIONS["fp1220"] else (FP1632_SCALE, 1 << 47)
    raw = np.rint(values * scale)  # round half to even, as Python's round()
    if not ((raw >= -limit) & (raw < limit)).all():  # NaN fails too
        return None
    if bits == PRECISIONS["fp1220"]:
        return raw.astype(np.int64)
    whole = raw.astype(np.int64)
    out = np.empty(values.shape, FP1632)
    out["fraction"], out["integer"] = whole & 0xFFFFFFFF, whole >> 32
    return out


@dataclass(frozen=True)
class _Layout:
    """The frame of one set of items: its bytes with every value zero, and where each item's values go."""

    template: np.ndarray  # uint8, read-only
    values: np.dtype  # fields v0, v1, ... at their offsets in the frame


@functools.lru_cache(maxsize=256)
def _layout(xdis: tuple[int, ...]) -> _Layout | None:
    """None when the payload is longer than an Xbus message holds (the reference raises the error)."""
    sizes = [item_size(SPEC_BY_BASE[xdi & TYPE_MASK], xdi) or 0 for xdi in xdis]
    payload = b"".join(
        struct.pack(">HB", xdi, size) + bytes(size) for xdi, size in zip(xdis, sizes, strict=True)
    )
    try:
        frame = build_frame(MID.MTDATA2, payload)
    except ProtocolError:
        return None
    header = len(frame) - len(payload) - 1
    values = np.dtype(
        {
            "names": [f"v{j}" for j in range(len(xdis))],
            "formats": [_field_type(xdi) for xdi in xdis],
            # each item's values follow its XDI and size
            "offsets": [header + 3 * (j + 1) + sum(sizes[:j]) for j in range(len(xdis))],
            "itemsize": len(frame),
        }
    )
    return _Layout(np.frombuffer(frame, np.uint8), values)


def _field_type(xdi: int) -> np.dtype:
    spec = SPEC_BY_BASE[xdi & TYPE_MASK]
    if spec.kind != DataKind.REAL:
        return np.dtype(spec.fmt)  # '>H', '>I', '>B'
    return np.dtype((REAL_TYPES[xdi & PRECISION_MASK], (spec.count,)))


def _whole_frames(layout: _Layout, count: int, values: Sequence[np.ndarray]) -> bytes:
    """The frames of ``count`` rows that carry the same items (``values``: each item's), one after another."""
    frames = np.empty(count, layout.values)
    raw = frames.view(np.uint8).reshape(count, layout.template.size)
    raw[:] = layout.template
    for j, column in enumerate(values):
        frames[f"v{j}"] = column
    raw[:, -1] = -raw[:, 1:-1].sum(axis=1, dtype=np.uint8)  # bytes after the preamble sum to 0 mod 256
    return raw.tobytes()


def mtdata2_frames(
    block: np.ndarray, present: np.ndarray, xdis: Sequence[int], clock_modulus: int
) -> list[bytes]:
    """One MTData2 frame per sample of ``block``: row ``i`` carries item ``j`` (``xdis[j]``) where
    ``present[i, j]``, in the order of ``xdis``."""
    named = {xdi: SPEC_BY_BASE[xdi & TYPE_MASK].name for xdi in xdis}
    values = {name: output_values(name, block, clock_modulus) for name in set(named.values())}
    wire = [_on_the_wire(values[named[xdi]], xdi) for xdi in xdis]
    groups: dict[tuple[bool, ...], list[int]] = {}  # the rows that carry the same items
    for row, carried in enumerate(map(tuple, present.tolist())):
        groups.setdefault(carried, []).append(row)
    frames = [b""] * block.size
    for carried, rows in groups.items():
        chosen = [j for j, carry in enumerate(carried) if carry]
        layout = _layout(tuple(xdis[j] for j in chosen))
        columns = [wire[j] for j in chosen]
        if layout is None or any(column is None for column in columns):
            return _frame_by_frame(values, present, xdis, named)
        some = rows if len(rows) < block.size else slice(None)
        data = _whole_frames(layout, len(rows), [column[some] for column in columns if column is not None])
        size = layout.template.size
        for i, row in enumerate(rows):
            frames[row] = data[i * size : (i + 1) * size]
    return frames


def _frame_by_frame(
    values: dict[str, np.ndarray], present: np.ndarray, xdis: Sequence[int], named: dict[int, str]
) -> list[bytes]:
    """The reference encoders row by row, for the blocks whose values they refuse (they raise the error),
    pack their own way, or that make a message longer than Xbus allows."""
    return [
        build_frame(
            MID.MTDATA2,
            encode_mtdata2(
                [
                    (xdi, values[named[xdi]][row].tolist())
                    for xdi, carry in zip(xdis, carried, strict=True)
                    if carry
                ]
            ),
        )
        for row, carried in enumerate(present.tolist())
    ]
