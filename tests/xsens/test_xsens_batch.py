"""Batch and streaming decoders: identical to the sequential framer + per-message decoder on any input."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from support.xsens_captures import SETS, capture
from tankdaq.errors import ProtocolError
from tankdaq.samples import SAMPLE_DTYPE
from tankdaq.xsens.column_decoder import DecodedBlock, decode_capture, to_samples
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import Frame, build_frame
from tankdaq.xsens.frame_scan import RUNNING_SUM_LIMIT
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import (
    GnssPvt,
    GnssSatellite,
    GnssSatInfo,
    MTData2Message,
    UtcTime,
    decode_mtdata2,
    encode_mtdata2,
    make_xdi,
)
from tankdaq.xsens.stream_decoder import StreamDecoder
from tankdaq.xsens.synthetic import decay_capture, decay_signals
from tankdaq.xsens.timebase import MODULUS_ONE_DAY, SampleTimeUnwrapper


def reference_decode(stream: bytes) -> tuple[list[MTData2Message], list[Frame], int, StreamFramer]:
    """What the sequential framer and the per-message decoder make of ``stream``."""
    framer = StreamFramer()
    messages, others, malformed = [], [], 0
    for frame in framer.feed(stream) + framer.finish():  # a capture: nothing follows its last byte
        if frame.mid != MID.MTDATA2:
            others.append(frame)
            continue
        try:
            messages.append(decode_mtdata2(frame.payload))
        except ProtocolError:
            malformed += 1
    return messages, others, malformed, framer


def assert_same_as_reference(block: DecodedBlock, stream: bytes) -> None:
    messages, others, malformed, framer = reference_decode(stream)
    assert block.n_messages == len(messages)
    for index, expected in enumerate(messages):
        got = block.message(index)
        assert dict(got) == dict(expected), index
        assert got.xdis == expected.xdis, index
        assert got.unknown_count == expected.unknown_count, index
    assert block.other_frames == others
    assert (
        block.frames, block.bad_checksums, block.skipped_bytes, block.pending_bytes, block.malformed,
        block.false_syncs,
    ) == (framer.frames, framer.bad_checksums, framer.skipped_bytes, framer.pending, malformed,
          framer.false_syncs)  # fmt: skip
    order = np.sort(np.concatenate([block.frame_index, block.other_index]))
    assert len(order) == framer.frames - malformed


def stream_in_chunks(stream: bytes, cuts: list[int]) -> DecodedBlock:
    decoder = StreamDecoder()
    points = sorted({min(c, len(stream)) for c in cuts})
    edges = [0, *points, len(stream)]
    blocks = [decoder.feed(stream[a:b]) for a, b in itertools.pairwise(edges)] + [decoder.finish()]
    merged = DecodedBlock.concat(blocks)
    assert decoder.pending == merged.pending_bytes
    assert decoder.messages == merged.n_messages
    assert decoder.bad_checksums == merged.bad_checksums and decoder.skipped_bytes == merged.skipped_bytes
    return merged


def assert_blocks_equal(a: DecodedBlock, b: DecodedBlock) -> None:
    assert a.n_messages == b.n_messages
    assert all(dict(a.message(i)) == dict(b.message(i)) and a.message(i).xdis == b.message(i).xdis
               for i in range(a.n_messages))  # fmt: skip
    assert a.other_frames == b.other_frames
    assert np.array_equal(a.frame_index, b.frame_index) and np.array_equal(a.other_index, b.other_index)
    assert (a.frames, a.bad_checksums, a.skipped_bytes, a.malformed, a.unknown_ids, a.false_syncs) == (
        b.frames,
        b.bad_checksums,
        b.skipped_bytes,
        b.malformed,
        b.unknown_ids,
        b.false_syncs,
    )


# ------------------------------------------------------------------------------------ real captures


@pytest.mark.parametrize("name", SETS)
@pytest.mark.slow
def test_real_captures_batch_and_stream_equal_per_message(name: str) -> None:
    data = capture(name).read_bytes()
    block = decode_capture(data)
    assert block.n_messages == 100
    assert_same_as_reference(block, data)
    assert_blocks_equal(stream_in_chunks(data, list(range(0, len(data), 333))), block)


# --------------------------------------------------------------------------------- random streams

LAYOUTS = [
    [("PacketCounter", "float32"), ("SampleTimeFine", "float32"), ("EulerAngles", "float32"),
     ("RateOfTurn", "float32"), ("Acceleration", "float32"), ("StatusWord", "float32")],
    [("PacketCounter", "float32"), ("EulerAngles", "fp1632"), ("LatLon", "fp1220"),
     ("StatusByte", "float32")],
    [("SampleTimeFine", "float32"), ("Quaternion", "float64"), ("Temperature", "fp1220")],
]  # fmt: skip
finite = st.floats(-1000, 1000, width=32)


@st.composite
def mtdata2_frames(draw: st.DrawFn) -> bytes:
    layout = draw(st.sampled_from(LAYOUTS))
    items: list[tuple[int, object]] = []
    for name, precision in layout:
        xdi = make_xdi(name, precision)
        if name in ("PacketCounter", "LocationId"):
            items.append((xdi, draw(st.integers(0, 0xFFFF))))
        elif name in ("SampleTimeFine", "StatusWord"):
            items.append((xdi, draw(st.integers(0, 0xFFFF_FFFF))))
        elif name == "StatusByte":
            items.append((xdi, draw(st.integers(0, 0xFF))))
        else:
            count = {"EulerAngles": 3, "RateOfTurn": 3, "Acceleration": 3, "LatLon": 2, "Quaternion": 4}.get(
                name, 1
            )
            values = tuple(draw(finite) for _ in range(count))
            items.append((xdi, values[0] if count == 1 else values))
    if draw(st.booleans()):  # an identifier tankdaq does not know, anywhere in the message
        items.insert(draw(st.integers(0, len(items))), (0xF0F0, draw(st.binary(max_size=6))))
    return build_frame(MID.MTDATA2, encode_mtdata2(items))


pieces = st.one_of(
    mtdata2_frames(),
    mtdata2_frames(),
    st.builds(
        build_frame, st.sampled_from([MID.GOTO_CONFIG_ACK, MID.ERROR, MID.WAKEUP]), st.binary(max_size=3)
    ),
    st.builds(lambda p: build_frame(MID.MTDATA2, p), st.binary(max_size=12)),  # often malformed items
    st.builds(lambda p: build_frame(MID.MTDATA2, p), st.binary(min_size=300, max_size=400)),  # extended
    st.binary(max_size=12),  # garbage, 0xFA included
    mtdata2_frames().map(lambda f: f[:-1] + bytes([(f[-1] + 1) & 0xFF])),  # bad checksum
    mtdata2_frames().map(lambda f: f[: len(f) // 2]),  # cut short
)


@settings(max_examples=120, deadline=None)
@given(st.lists(pieces, max_size=25).map(b"".join), st.lists(st.integers(0, 3000), max_size=12))
@pytest.mark.slow
def test_batch_equals_reference_and_stream_under_any_chunking(stream: bytes, cuts: list[int]) -> None:
    block = decode_capture(stream)
    assert_same_as_reference(block, stream)
    assert_blocks_equal(stream_in_chunks(stream, cuts), block)


def test_structured_outputs_in_mixed_layouts_match_per_message() -> None:
    structured = [
        (make_xdi("UtcTime"), UtcTime(121_900_000, 2019, 1, 20, 13, 47, 24, 0x37)),
        (make_xdi("RawAccGyrMagTemp"), (*range(100, 109), -300)),
        (make_xdi("DeviceId"), 0x0778_0000_1234_5678),
        (make_xdi("GnssSatInfo"), GnssSatInfo(49666750, 2, 0, 0, 0, (GnssSatellite(0, 5, 40, 13),) * 2)),
        (make_xdi("GnssPvtData"), GnssPvt(*range(35))),
        (make_xdi("LatLon", "fp1632"), (57.679442145396024, 11.88257829961367)),
    ]
    inertial = [(make_xdi("PacketCounter"), 7), (make_xdi("EulerAngles", "fp1220"), (1.5, -2.25, 179.0))]
    stream = b"".join(
        build_frame(MID.MTDATA2, encode_mtdata2(structured if i % 3 == 0 else inertial)) for i in range(12)
    )
    block = decode_capture(stream)
    assert block.n_messages == 12 and block.present["GnssPvtData"].sum() == 4
    assert np.isnan(block.columns["LatLon"][1]).all()  # absent rows of a real column are NaN
    assert_same_as_reference(block, stream)
    assert_blocks_equal(stream_in_chunks(stream, [50, 51, 400]), block)


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.slow
def test_long_corrupted_capture_uses_the_row_sum_path_and_still_matches(seed: int) -> None:
    rng = np.random.default_rng(seed)
    clean = np.frombuffer(decay_capture(6000, seed=seed), dtype=np.uint8).copy()
    flips = rng.choice(clean.size, size=40, replace=False)
    clean[flips] = rng.integers(0, 256, size=flips.size)  # corrupt frames, some into 0xFA
    chunks = np.array_split(clean, 30)
    extras = [
        build_frame(MID.GOTO_CONFIG_ACK),
        bytes(rng.integers(0, 256, 50, dtype=np.uint8)),
        b"\xfa\xff\x36",
    ]
    stream = b"".join(chunk.tobytes() + extras[i % 3] for i, chunk in enumerate(chunks))
    assert len(stream) > RUNNING_SUM_LIMIT
    block = decode_capture(stream)
    assert block.bad_checksums > 0
    assert_same_as_reference(block, stream)
    assert_blocks_equal(stream_in_chunks(stream, list(range(0, len(stream), 4096))), block)


def test_trailing_partial_frame_is_pending_not_skipped() -> None:
    data = decay_capture(10)
    block = decode_capture(data[:-20])
    assert block.n_messages == 9 and block.pending_bytes == 69 - 20 and block.skipped_bytes == 0


# ------------------------------------------------------------------------------------------ samples


def test_samples_from_a_known_decay_across_the_day_wrap() -> None:
    start = MODULUS_ONE_DAY - 250  # wraps after 3 samples at 100 Hz
    data = decay_capture(500, seed=4, start_ticks=start)
    truth = decay_signals(500, 100.0, 4, start_ticks=start)
    unwrapper = SampleTimeUnwrapper()
    decoder = StreamDecoder()
    blocks = [decoder.feed(data[i : i + 1000]) for i in range(0, len(data), 1000)]
    assert decoder.pending == 69  # the last frame waits for the byte after it ...
    samples = np.concatenate([to_samples(b, unwrapper) for b in [*blocks, decoder.flush()]])  # ... or a flush
    assert samples.dtype == SAMPLE_DTYPE and samples.size == 500
    assert np.array_equal(samples["ticks"], start + 100 * np.arange(500))
    assert np.allclose(np.diff(samples["t"]), 0.01, rtol=0, atol=1e-9)
    euler_deg = truth["EulerAngles"].astype(np.float32).astype(np.float64)
    assert np.array_equal(samples["roll"], np.deg2rad(euler_deg[:, 0]))
    assert np.array_equal(samples["yaw"], np.deg2rad(euler_deg[:, 2]))
    assert np.array_equal(samples["q"], truth["RateOfTurn"][:, 1].astype(np.float32))
    assert np.array_equal(samples["az"], truth["Acceleration"][:, 2].astype(np.float32))
    assert np.array_equal(samples["counter"], np.arange(500))
    assert np.all(samples["status"] == 7)


def test_samples_skip_gnss_messages_and_take_status_byte() -> None:
    inertial = encode_mtdata2(
        [(0x1020, 1), (0x1060, 5000), (make_xdi("RateOfTurn"), (0.1, 0.2, 0.3)), (0xE010, 5)]
    )
    gnss = encode_mtdata2([(0x1020, 2), (0x1060, 4600), (make_xdi("LatLon"), (57.7, 11.9))])
    data = build_frame(MID.MTDATA2, inertial) + build_frame(MID.MTDATA2, gnss)
    samples = to_samples(decode_capture(data), SampleTimeUnwrapper())
    assert samples.size == 1
    assert samples["status"][0] == 5 and samples["counter"][0] == 1 and samples["ticks"][0] == 5000
    assert np.isnan(samples["roll"][0]) and samples["p"][0] == np.float32(0.1)


def test_samples_leave_out_messages_that_cannot_be_samples_and_never_raise() -> None:
    """Euler angles in another frame, or a time beyond the one-day clock: a corrupted frame, left out."""

    def message(counter: int, ticks: int, frame: str = "ENU") -> list[tuple[int, object]]:
        euler = make_xdi("EulerAngles", "float32", frame)
        return [(make_xdi("PacketCounter"), counter), (0x1060, ticks), (euler, (1.0, 2.0, 3.0))]

    messages = (message(1, 1000), message(2, 1100, "NED"), message(3, MODULUS_ONE_DAY + 5), message(4, 1300))
    stream = b"".join(build_frame(MID.MTDATA2, encode_mtdata2(items)) for items in messages)
    samples = to_samples(decode_capture(stream), SampleTimeUnwrapper())
    assert samples["counter"].tolist() == [1, 4] and samples["ticks"].tolist() == [1000, 1300]
