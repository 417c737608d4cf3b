"""Long realistic MTData2 captures built with array code, for benchmarks and decoder tests.

A free roll decay (damped sine) sampled by the decay output set (PacketCounter,
SampleTimeFine, EulerAngles, RateOfTurn, Acceleration, StatusWord, float32): 69-byte frames,
as an MTi-G-710 sends them. Building a million frames one by one in Python would take
seconds; here every field is written for all frames at once.
"""

from __future__ import annotations

import numpy as np

from .constants import MASTER_BID, MID, PREAMBLE
from .mtdata2 import make_xdi
from .timebase import MODULUS_ONE_DAY, TICKS_PER_SECOND

#: (name, values per item, numpy big-endian dtype) of the decay message, in wire order.
DECAY_ITEMS: tuple[tuple[str, int, str], ...] = (
    ("PacketCounter", 1, ">u2"),
    ("SampleTimeFine", 1, ">u4"),
    ("EulerAngles", 3, ">f4"),
    ("RateOfTurn", 3, ">f4"),
    ("Acceleration", 3, ">f4"),
    ("StatusWord", 1, ">u4"),
)


def decay_signals(
    n_frames: int, rate_hz: float, seed: int, start_ticks: int = 123_456
) -> dict[str, np.ndarray]:
    """Device-unit values of a lightly damped roll decay with sensor noise (Euler in degrees)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / rate_hz
    period_s, damping = 1.6, 0.03
    omega = 2 * np.pi / period_s
    cycle = t % 60.0  # a fresh release every minute, as in a test campaign
    roll_rad = np.deg2rad(8.0) * np.exp(-damping * omega * cycle) * np.cos(omega * cycle)
    rate = np.gradient(roll_rad, t) if n_frames > 1 else np.zeros(n_frames)
    noise = rng.normal(scale=1e-3, size=(n_frames, 9))
    euler_deg = np.column_stack([np.rad2deg(roll_rad), 0.2 + noise[:, 0], 45.0 + noise[:, 1]])
    rate_of_turn = np.column_stack([rate, noise[:, 2], noise[:, 3]])
    acc = np.column_stack([noise[:, 4], -9.81 * np.sin(roll_rad), 9.81 * np.cos(roll_rad)]) + noise[:, 6:9]
    return {
        "PacketCounter": np.arange(n_frames) % 65536,
        "SampleTimeFine": (start_ticks + np.arange(n_frames) * round(TICKS_PER_SECOND / rate_hz))
        % MODULUS_ONE_DAY,
        "EulerAngles": euler_deg,
        "RateOfTurn": rate_of_turn,
        "Acceleration": acc,
        "StatusWord": np.full(n_frames, 0x00000007),
    }


def decay_capture(n_frames: int, rate_hz: float = 100.0, seed: int = 0, start_ticks: int = 123_456) -> bytes:
    """Raw bytes of ``n_frames`` consecutive decay MTData2 frames (float32, 69 bytes each)."""
    signals = decay_signals(n_frames, rate_hz, seed, start_ticks)
    columns: list[np.ndarray] = []
    for name, count, dtype in DECAY_ITEMS:
        size = count * np.dtype(dtype).itemsize
        header = np.frombuffer(make_xdi(name).to_bytes(2, "big") + bytes((size,)), dtype=np.uint8)
        columns.append(np.broadcast_to(header, (n_frames, 3)))
        values = np.ascontiguousarray(signals[name], dtype=dtype).reshape(n_frames, count)
        columns.append(values.view(np.uint8).reshape(n_frames, size))
    payload = np.concatenate(columns, axis=1)
    head = np.broadcast_to(
        np.array([PREAMBLE, MASTER_BID, MID.MTDATA2, payload.shape[1]], np.uint8), (n_frames, 4)
    )
    checksum = (-(head[:, 1:].sum(axis=1) + payload.sum(axis=1, dtype=np.int64))) % 256
    frames = np.concatenate([head, payload, checksum.astype(np.uint8)[:, None]], axis=1)
    return frames.tobytes()


#: A header that looks like the start of a data frame: what line noise most often fakes.
STRAY_HEADER = bytes((PREAMBLE, MASTER_BID, MID.MTDATA2))


def noisy_capture(
    n_frames: int, corrupt_fraction: float = 0.03, stray_fraction: float = 0.03, seed: int = 0
) -> tuple[bytes, np.ndarray]:
    """A decay capture with one byte corrupted in ``corrupt_fraction`` of the frames and stray
    ``FA FF 36`` headers inserted at random byte positions (``stray_fraction`` per frame), plus
    the mask of frames that arrive intact (untouched, no stray header inside them).
    """
    rng = np.random.default_rng([seed, 7])
    frames = np.frombuffer(decay_capture(n_frames, seed=seed), np.uint8).reshape(n_frames, -1).copy()
    size = frames.shape[1]
    corrupt = rng.random(n_frames) < corrupt_fraction
    rows = np.flatnonzero(corrupt)
    frames[rows, rng.integers(0, size, rows.size)] ^= rng.integers(1, 256, rows.size, dtype=np.uint8)
    positions = np.sort(rng.integers(0, frames.size, int(n_frames * stray_fraction)))
    # A stray header before a frame's preamble leaves that frame whole; so does one right after
    # the frame's own FA FF 36 (the stray's copy of them then starts the intact frame).
    inside = (positions % size != 0) & (positions % size != len(STRAY_HEADER))
    intact = ~corrupt
    intact[positions[inside] // size] = False
    stream = np.insert(frames.ravel(), np.repeat(positions, len(STRAY_HEADER)),
                       np.tile(np.frombuffer(STRAY_HEADER, np.uint8), positions.size))  # fmt: skip
    return stream.tobytes(), intact
