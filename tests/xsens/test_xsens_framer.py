"""The framer never trades intact frames for false ones: 10^5 frames of corruption and stray headers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.errors import ProtocolError
from tankdaq.xsens.column_decoder import decode_capture
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import Frame, build_frame
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import decode_mtdata2, make_xdi, payload_well_formed
from tankdaq.xsens.stream_decoder import StreamDecoder
from tankdaq.xsens.synthetic import STRAY_HEADER, decay_capture, noisy_capture

FRAMES = 100_000
FRAME_BYTES = 69


@pytest.fixture(scope="module")
def noisy() -> tuple[bytes, np.ndarray]:
    return noisy_capture(FRAMES, corrupt_fraction=0.03, stray_fraction=0.03, seed=11)


@pytest.mark.slow
def test_sequential_framer_keeps_every_intact_frame_and_invents_none(noisy) -> None:
    stream, intact = noisy
    clean = np.frombuffer(decay_capture(FRAMES, seed=11), np.uint8).reshape(FRAMES, FRAME_BYTES)
    framer = StreamFramer()
    frames = framer.feed(stream) + framer.flush()
    got = np.frombuffer(b"".join(f.to_bytes() for f in frames), np.uint8).reshape(-1, FRAME_BYTES)
    assert got.shape[0] == int(intact.sum())
    np.testing.assert_array_equal(got, clean[intact])  # exactly the intact frames, in order
    assert framer.bad_checksums > 0
    assert framer.false_syncs > 0  # false headers passed the checksum and were turned away


@pytest.mark.slow
def test_streaming_decoder_keeps_every_intact_frame_and_invents_none(noisy) -> None:
    stream, intact = noisy
    expected = decode_capture(decay_capture(FRAMES, seed=11))
    decoder = StreamDecoder()
    blocks = [decoder.feed(stream[i : i + 4096]) for i in range(0, len(stream), 4096)] + [decoder.flush()]
    got = np.concatenate([b.columns["SampleTimeFine"] for b in blocks if b.n_messages])
    np.testing.assert_array_equal(got, expected.columns["SampleTimeFine"][intact])
    roll = np.concatenate([b.columns["EulerAngles"] for b in blocks if b.n_messages])
    np.testing.assert_array_equal(roll, expected.columns["EulerAngles"][intact])
    assert decoder.false_syncs > 0 and decoder.malformed == 0


def test_a_false_frame_that_passes_the_checksum_is_rejected_and_the_real_ones_kept() -> None:
    real = decay_capture(3)
    # A stray header whose length makes the checksum hold over the real bytes behind it:
    # without confirmation it would swallow the first real frame.
    header = bytes((0xFA, 0xFF, 0x36))
    length = next(n for n in range(1, 200) if (0xFF + 0x36 + n + sum(real[: n + 1])) % 256 == 0)
    stream = b"\x00\x01" + header + bytes((length,)) + real
    framer = StreamFramer()
    frames = framer.feed(stream) + framer.flush()
    assert b"".join(f.to_bytes() for f in frames) == real and len(frames) == 3
    assert framer.false_syncs == 1


def test_a_frame_waits_for_its_successor_and_a_quiet_line_releases_it() -> None:
    ack = build_frame(MID.GOTO_CONFIG_ACK)
    framer = StreamFramer()
    assert framer.feed(b"\x13\x37" + ack) == []  # out of sync: does a frame start after it?
    assert framer.pending == len(ack)
    assert framer.flush() == [Frame(0xFF, MID.GOTO_CONFIG_ACK, b"")]
    assert framer.pending == 0 and framer.false_syncs == 0
    assert framer.feed(b"\x13" + ack + ack) == [Frame(0xFF, MID.GOTO_CONFIG_ACK, b"")]  # the next confirms it
    assert framer.pending == len(ack)  # which itself waits for its own successor


@pytest.mark.slow
def test_the_sizes_check_agrees_with_the_decoder_on_random_payloads() -> None:
    rng = np.random.default_rng(4)
    names = ("PacketCounter", "EulerAngles", "DeviceId", "GnssSatInfo", "UtcTime")
    known = [make_xdi(name) for name in names]
    outcomes = set()
    for _ in range(20_000):
        items = []
        for _ in range(rng.integers(0, 4)):
            xdi = int(rng.choice(known)) if rng.random() < 0.8 else int(rng.integers(0, 1 << 16))
            size = int(rng.integers(0, 40))
            items.append(xdi.to_bytes(2, "big") + bytes((size,)) + rng.bytes(size))
        payload = b"".join(items)
        payload = payload[: rng.integers(0, len(payload) + 1)]  # often cut inside an item
        try:
            decode_mtdata2(payload)
            decodes = True
        except ProtocolError:
            decodes = False
        assert payload_well_formed(payload) == decodes, payload.hex()
        outcomes.add(decodes)
    assert outcomes == {True, False}


def test_a_framer_hands_its_held_bytes_to_the_decoder_that_takes_the_stream_over() -> None:
    """The driver's hand-shake framer passes on a half-read frame: the stream decoder completes it."""
    ack, data = build_frame(MID.GOTO_MEASUREMENT + 1), build_frame(MID.MTDATA2, bytes(10))
    framer = StreamFramer()
    assert [f.mid for f in framer.feed(ack + data[:7])] == [MID.GOTO_MEASUREMENT + 1]
    held = framer.take_pending()
    assert held == data[:7] and framer.pending == 0
    decoder = StreamFramer()
    assert decoder.feed(held) == [] and decoder.feed(data[7:]) + decoder.flush() == [
        Frame(0xFF, MID.MTDATA2, bytes(10))
    ]


def _rows(data: bytes) -> list[bytes]:
    return [data[i : i + FRAME_BYTES] for i in range(0, len(data), FRAME_BYTES)]


def _in_order(wanted: list[bytes], got: list[bytes]) -> bool:
    """``wanted`` is a subsequence of ``got`` (a frame the noise happened to leave whole may be extra)."""
    found = iter(got)
    return all(any(row == other for other in found) for row in wanted)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    n=st.integers(1, 40),
    loss=st.sampled_from(["stray header", "corrupted frame", "cut frame", "broken header"]),
    chunk=st.integers(1, 300),
)
@pytest.mark.slow
def test_a_stream_that_ends_right_after_a_held_frame_loses_no_intact_frame(
    seed: int, n: int, loss: str, chunk: int
) -> None:
    """The last frame follows a loss of sync and nothing follows it: the end of the stream releases it.

    (Each loss starts with a preamble: a frame followed by garbage is not confirmed, by design.)"""
    noisy, intact = noisy_capture(n, corrupt_fraction=0.2, stray_fraction=0.2, seed=seed)
    clean = _rows(decay_capture(n, seed=seed))
    corrupted = bytearray(clean[0])
    corrupted[10] ^= 0x5A
    lost = {"stray header": STRAY_HEADER, "corrupted frame": bytes(corrupted), "cut frame": clean[0][:20],
            "broken header": b"\xfa\x13\x37"}[loss]  # fmt: skip
    stream = noisy + lost + clean[-1]
    wanted = [row for row, whole in zip(clean, intact, strict=True) if whole] + [clean[-1]]

    framer = StreamFramer()
    got = [f.to_bytes() for f in framer.feed(stream) + framer.finish()]
    assert _in_order(wanted, got) and got[-1] == clean[-1]
    decoder = StreamDecoder()
    blocks = [decoder.feed(stream[i : i + chunk]) for i in range(0, len(stream), chunk)] + [decoder.finish()]
    streamed = np.concatenate([b.columns["SampleTimeFine"] for b in blocks if b.n_messages])
    batch = decode_capture(stream)
    expected = np.array([int.from_bytes(row[12:16], "big") for row in got])  # SampleTimeFine's bytes
    np.testing.assert_array_equal(batch.columns["SampleTimeFine"], expected)
    np.testing.assert_array_equal(streamed, expected)
