"""Framing: worked frames from the LLCP, parse errors, and the stream framer under chunking and garbage."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.errors import ProtocolError
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import Frame, build_frame, checksum_ok, parse_frame
from tankdaq.xsens.framer import StreamFramer

# Reference §1.3: frames quoted from the LLCP and drivers.
WORKED_FRAMES = [
    (MID.GOTO_CONFIG, b"", "FA FF 30 00 D1"),
    (MID.GOTO_CONFIG_ACK, b"", "FA FF 31 00 D0"),
    (MID.GOTO_MEASUREMENT, b"", "FA FF 10 00 F1"),
    (MID.WAKEUP, b"", "FA FF 3E 00 C3"),
    (MID.WAKEUP_ACK, b"", "FA FF 3F 00 C2"),
    (MID.RESET, b"", "FA FF 40 00 C1"),
    (MID.REQ_DID, b"", "FA FF 00 00 01"),
    (MID.REQ_BAUDRATE, b"", "FA FF 18 00 E9"),
    (MID.SET_BAUDRATE, b"\x80", "FA FF 18 01 80 68"),
    (MID.SET_BAUDRATE, b"\x02", "FA FF 18 01 02 E6"),
    (MID.BAUDRATE_ACK, b"", "FA FF 19 00 E8"),
    (MID.RESTORE_FACTORY_DEF, b"", "FA FF 0E 00 F3"),
    (MID.OUTPUT_CONFIGURATION, b"", "FA FF C0 00 41"),
    (MID.REQ_FW_REV, b"", "FA FF 12 00 EF"),
    (MID.REQ_CONFIGURATION, b"", "FA FF 0C 00 F5"),
    (MID.FILTER_PROFILE, b"\x00\x02", "FA FF 64 02 00 02 99"),
    (MID.FILTER_PROFILE_ACK, b"", "FA FF 65 00 9C"),
    (MID.STRING_OUTPUT_TYPE, b"\x00\x00", "FA FF 8E 02 00 00 71"),
    (MID.ERROR, b"\x04", "FA FF 42 01 04 BA"),
]


@pytest.mark.parametrize(("mid", "payload", "wire"), WORKED_FRAMES)
def test_worked_frames_build_and_parse(mid: int, payload: bytes, wire: str) -> None:
    raw = bytes.fromhex(wire)
    assert build_frame(mid, payload) == raw
    assert checksum_ok(raw)
    assert parse_frame(raw) == Frame(0xFF, mid, payload)


def test_extended_length_frame_round_trip() -> None:
    payload = bytes(range(256)) * 4 + b"xyz"  # 1027 bytes: needs FF LENH LENL
    raw = build_frame(MID.MTDATA2, payload)
    assert raw[3] == 0xFF and raw[4:6] == (1027).to_bytes(2, "big")
    assert len(raw) == 6 + 1027 + 1
    assert parse_frame(raw).payload == payload
    assert build_frame(MID.MTDATA2, bytes(254))[3] == 254  # the largest standard length
    assert build_frame(MID.MTDATA2, bytes(255))[3] == 0xFF


def test_build_frame_rejects_oversize_data() -> None:
    with pytest.raises(ProtocolError, match="2048"):
        build_frame(MID.MTDATA2, bytes(2049))


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        ("FF FF 30 00 D1", "preamble"),
        ("FA FF 30 00 D2", "checksum"),
        ("FA FF 30 01 D1", "length"),
        ("FA FF 30", "length"),
    ],
)
def test_parse_frame_rejects_bad_frames(raw: str, reason: str) -> None:
    with pytest.raises(ProtocolError, match=reason):
        parse_frame(bytes.fromhex(raw))


def test_frame_name_for_known_and_unknown_ids() -> None:
    assert Frame(0xFF, 0x31, b"").name == "GOTO_CONFIG_ACK"
    assert Frame(0xFF, 0xEE, b"").name == "0xEE"


# ------------------------------------------------------------------------------------------ framer

frame_specs = st.tuples(
    st.sampled_from([0xFF, 0x01]),
    st.integers(0, 255).filter(lambda mid: mid != MID.MTDATA2),  # random data is no MTData2 payload
    st.one_of(st.binary(max_size=40), st.binary(min_size=255, max_size=600)),
)
# Garbage and corrupted frames never contain a stray 0xFA after the preamble, so no byte
# sequence in them can be mistaken for a frame: then "every intact frame, nothing else" is exact.
no_preamble = st.binary(max_size=30).map(lambda b: b.replace(b"\xfa", b"\x00"))


@st.composite
def noisy_streams(draw: st.DrawFn) -> tuple[bytes, list[Frame], int]:
    """A stream opened mid-frame (garbage first), then intact and checksum-corrupted frames."""
    stream = bytearray(draw(no_preamble))
    sent: list[Frame] = []
    corrupted = 0
    for bid, mid, payload in draw(st.lists(frame_specs, max_size=12)):
        if draw(st.booleans()) or b"\xfa" in build_frame(mid, payload, bid)[1:]:
            sent.append(Frame(bid, mid, payload))
            stream += build_frame(mid, payload, bid)
        else:
            bad = bytearray(build_frame(mid, payload, bid))
            bad[-1] = draw(st.sampled_from([v for v in range(256) if v not in (bad[-1], 0xFA)]))
            corrupted += 1
            stream += bad
    return bytes(stream), sent, corrupted


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({min(c, len(data)) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


@settings(max_examples=150, deadline=None)
@given(noisy_streams(), st.lists(st.integers(0, 4000), max_size=20))
@pytest.mark.slow
def test_framer_recovers_every_intact_frame_under_any_chunking(
    case: tuple[bytes, list[Frame], int], cuts: list[int]
) -> None:
    stream, sent, corrupted = case
    framer = StreamFramer()
    got = [frame for chunk in split(stream, cuts) for frame in framer.feed(chunk)] + framer.flush()
    assert got == sent
    assert framer.false_syncs == 0
    assert framer.frames == len(sent)
    assert framer.bad_checksums == corrupted
    assert framer.pending == 0
    assert framer.skipped_bytes == len(stream) - sum(len(f.to_bytes()) for f in sent)


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=10))
def test_framer_never_raises_and_accounts_for_every_byte(garbage: bytes, cuts: list[int]) -> None:
    framer = StreamFramer()
    frames = [frame for chunk in split(garbage, cuts) for frame in framer.feed(chunk)]
    assert all(checksum_ok(f.to_bytes()) for f in frames)
    used = sum(len(f.to_bytes()) for f in frames)
    assert used + framer.skipped_bytes + framer.pending == len(garbage)


def test_framer_resyncs_on_a_preamble_inside_a_corrupted_frame() -> None:
    good = build_frame(MID.GOTO_CONFIG_ACK)
    # A frame header whose length swallows the real frames behind it; its checksum is wrong, so
    # the framer must step one byte and find the real preamble inside it.
    bogus = bytes.fromhex("FA FF 36 08") + good * 3
    framer = StreamFramer()
    assert framer.feed(bogus) + framer.flush() == [Frame(0xFF, MID.GOTO_CONFIG_ACK, b"")] * 3
    assert framer.bad_checksums == 1


def test_framer_skips_lengths_over_the_bound_without_waiting() -> None:
    good = build_frame(MID.WAKEUP)
    framer = StreamFramer(max_length=100)
    frames = framer.feed(bytes.fromhex("FA FF 36 FF 10 00") + good) + framer.flush()
    assert frames == [Frame(0xFF, MID.WAKEUP, b"")]
    assert framer.skipped_bytes == 6
