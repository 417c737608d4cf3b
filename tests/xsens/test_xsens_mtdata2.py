"""MTData2 codec: the LLCP worked frame, round trips of every identifier, and malformed payloads."""

from __future__ import annotations

import math
import re
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.errors import ProtocolError
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame, parse_frame
from tankdaq.xsens.mtdata2 import (
    DATA_SPECS,
    FP1220_SCALE,
    FP1632_SCALE,
    PVT_STRUCT,
    DataSpec,
    GnssPvt,
    GnssSatellite,
    GnssSatInfo,
    UtcTime,
    decode_mtdata2,
    describe_xdi,
    encode_mtdata2,
    make_xdi,
    to_jsonable,
)

# LLCP p. 67: a real MTi-G-710 MTData2 frame (reference §1.3).
LLCP_FRAME = bytes.fromhex(
    "FA FF 36 31 10 20 02 DF C5 10 60 04 00 45 9D A0"
    " 40 20 0C BE DC 9A FA 3F 54 9F 37 41 1C BB 70"
    " 80 20 0C BB AA 5C 80 3B 8C 55 01 BB 81 33 00"
    " E0 20 04 00 00 00 81 45"
)


def test_llcp_worked_mtdata2_frame() -> None:
    frame = parse_frame(LLCP_FRAME)
    assert frame.mid == MID.MTDATA2
    msg = decode_mtdata2(frame.payload)
    assert list(msg) == ["PacketCounter", "SampleTimeFine", "Acceleration", "RateOfTurn", "StatusWord"]
    assert msg["PacketCounter"] == 57285
    assert msg["SampleTimeFine"] == 4_562_336
    assert msg["StatusWord"] == 0x81
    assert msg["Acceleration"] == pytest.approx((-0.4309, 0.8306, 9.7958), abs=5e-5)
    assert msg["RateOfTurn"] == pytest.approx((-0.00520, 0.00428, -0.00394), abs=5e-6)
    assert msg.precision("Acceleration") == "float32"
    assert encode_mtdata2([(msg.xdis[name], msg[name]) for name in msg]) == frame.payload


def test_make_xdi_format_bits() -> None:
    assert make_xdi("Quaternion", "fp16.32", "NED") == 0x2016  # reference §2.3 example
    assert make_xdi("EulerAngles") == 0x2030
    assert make_xdi("LatLon", "FP12.20") == 0x5041
    assert make_xdi("VelocityXYZ", "float64", "NWU") == 0xD01B
    assert describe_xdi(0x2016) == "Quaternion(NED,fp1632)"
    assert describe_xdi(0x1020) == "PacketCounter"


@pytest.mark.parametrize(
    ("name", "precision", "frame", "match"),
    [
        ("Acceleration", "float32", "NED", "frame"),
        ("PositionEcef", "fp1220", "ENU", "cannot be sent"),
        ("PacketCounter", "float64", "ENU", "cannot be sent"),
        ("EulerAngles", "float16", "ENU", "unknown precision"),
        ("Euler", "float32", "ENU", "unknown MTData2 output"),
    ],
)
def test_make_xdi_rejects_impossible_combinations(name: str, precision: str, frame: str, match: str) -> None:
    with pytest.raises(ProtocolError, match=match):
        make_xdi(name, precision, frame)


# ---------------------------------------------------------------------------- round-trip property

COMBINATIONS = [(spec, p, f) for spec in DATA_SPECS for p in spec.precisions() for f in spec.frames()]

u8, u16, u32 = st.integers(0, 0xFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF_FFFF)
FIELD_STRATEGIES = {"B": u8, "H": u16, "I": u32, "i": st.integers(-(2**31), 2**31 - 1)}


def struct_codes(fmt: str) -> list[str]:
    """'>IH2B' -> ['I', 'H', 'B', 'B']: one code per field of a struct format."""
    return [code for count, code in re.findall(r"(\d*)(\w)", fmt) for _ in range(int(count or 1))]


def real_strategy(precision: str) -> st.SearchStrategy[float]:
    """Values exactly representable in the precision, so the round trip must be bit exact."""
    if precision == "float32":
        return st.floats(width=32, allow_nan=False, allow_infinity=False)
    if precision == "float64":
        return st.floats(allow_nan=False, allow_infinity=False)
    if precision == "fp1220":
        return st.integers(-(2**31), 2**31 - 1).map(lambda raw: raw / FP1220_SCALE)
    return st.integers(-(2**47), 2**47 - 1).map(lambda raw: raw / FP1632_SCALE)


def value_strategy(spec: DataSpec, precision: str) -> st.SearchStrategy[object]:
    if spec.kind == "real":
        values = st.tuples(*[real_strategy(precision)] * spec.count)
        return values.map(lambda v: v[0]) if spec.count == 1 else values
    if spec.kind == "int":
        return st.integers(0, 2 ** (8 * struct.calcsize(spec.fmt)) - 1)
    if spec.kind == "ints":
        return st.tuples(*[u16] * 9, st.integers(-(2**15), 2**15 - 1))
    if spec.kind == "utc":
        return st.builds(UtcTime, u32, u16, u8, u8, u8, u8, u8, u8)
    if spec.kind == "pvt":
        return st.builds(GnssPvt, *[FIELD_STRATEGIES[code] for code in struct_codes(PVT_STRUCT.format)])
    if spec.kind == "satinfo":
        sats = st.lists(st.builds(GnssSatellite, u8, u8, u8, u8), max_size=40).map(tuple)
        return st.builds(GnssSatInfo, u32, u8, u8, u8, u8, sats)
    return st.one_of(u32, st.integers(2**32, 2**64 - 1))  # DeviceId: 4 or 8 bytes


@st.composite
def messages(draw: st.DrawFn) -> list[tuple[int, object]]:
    chosen = draw(
        st.lists(st.sampled_from(COMBINATIONS), min_size=1, max_size=6, unique_by=lambda c: c[0].name)
    )
    return [(make_xdi(spec.name, p, f), draw(value_strategy(spec, p))) for spec, p, f in chosen]


def same(a: object, b: object) -> bool:
    """Bit-exact equality that also treats -0.0 and 0.0 as different."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b and math.copysign(1, a) == math.copysign(1, b)
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@pytest.mark.parametrize(("spec", "precision", "frame"), COMBINATIONS, ids=lambda v: getattr(v, "name", v))
@settings(max_examples=15, deadline=None)
@given(data=st.data())
@pytest.mark.slow
def test_round_trip_every_identifier_precision_frame(
    spec: DataSpec, precision: str, frame: str, data: st.DataObject
) -> None:
    value = data.draw(value_strategy(spec, precision))
    xdi = make_xdi(spec.name, precision, frame)
    msg = decode_mtdata2(encode_mtdata2([(xdi, value)]))
    assert list(msg) == [spec.name]
    assert msg.xdis[spec.name] == xdi
    assert msg.precision(spec.name) == precision
    assert msg.frame(spec.name) == frame
    assert same(msg[spec.name], value)


@settings(max_examples=200, deadline=None)
@given(messages())
@pytest.mark.slow
def test_round_trip_whole_messages_through_frames(items: list[tuple[int, object]]) -> None:
    payload = encode_mtdata2(items)
    msg = decode_mtdata2(parse_frame(build_frame(MID.MTDATA2, payload)).payload)
    assert [msg.xdis[name] for name in msg] == [xdi for xdi, _ in items]
    for xdi, value in items:
        name = describe_xdi(xdi).split("(")[0]
        assert msg[name] == value


def test_fixed_point_encoding_matches_the_reference_rule() -> None:
    # FP12.20: int32 BE of round(x * 2^20); FP16.32: uint32 BE fraction, then int16 BE integer part.
    assert encode_mtdata2([(make_xdi("Temperature", "fp1220"), -1.5)])[3:] == struct.pack(">i", -3 << 19)
    raw = round(-1.25 * 2**32) & 0xFFFF_FFFF_FFFF
    expected = struct.pack(">IH", raw & 0xFFFF_FFFF, raw >> 32)
    assert encode_mtdata2([(make_xdi("Temperature", "fp1632"), -1.25)])[3:] == expected
    assert decode_mtdata2(bytes.fromhex("0812 06 40000000 FFFF"))["Temperature"] == -0.75


def test_fixed_point_rejects_out_of_range() -> None:
    with pytest.raises(ProtocolError, match=r"FP12\.20"):
        encode_mtdata2([(make_xdi("Temperature", "fp1220"), 2048.0)])
    with pytest.raises(ProtocolError, match=r"FP16\.32"):
        encode_mtdata2([(make_xdi("Temperature", "fp1632"), -32769.0)])


def test_unknown_identifiers_are_skipped_by_size_and_counted() -> None:
    payload = encode_mtdata2([(0x1020, 7), (0xF0F0, b"\x01\x02\x03"), (0x0F00, b""), (0xE020, 5)])
    msg = decode_mtdata2(payload)
    assert dict(msg) == {"PacketCounter": 7, "StatusWord": 5}
    assert msg.unknown_xdis == (0xF0F0, 0x0F00)
    assert msg.unknown_count == 2


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        ("1020 02 0001 E020", "item header"),
        ("1020 03 0001", "claims 3 bytes"),
        ("1020 01 00", "needs 2 data bytes"),
        ("2030 08 0000000000000000", "needs 12 data bytes"),
        ("7020 09 000000000000000000", "satellite"),
    ],
)
def test_sizes_that_do_not_add_up_are_rejected(payload: str, match: str) -> None:
    with pytest.raises(ProtocolError, match=match):
        decode_mtdata2(bytes.fromhex(payload))


def test_encode_rejects_wrong_value_shapes() -> None:
    with pytest.raises(ProtocolError, match="takes 3 values"):
        encode_mtdata2([(make_xdi("EulerAngles"), (1.0, 2.0))])
    with pytest.raises(ProtocolError, match="PacketCounter"):
        encode_mtdata2([(make_xdi("PacketCounter"), 70000)])
    with pytest.raises(ProtocolError, match="as bytes"):
        encode_mtdata2([(0xF0F0, 3)])


def test_utc_time_iso_and_json_forms() -> None:
    utc = UtcTime(121_900_000, 2019, 1, 20, 13, 47, 24, 0x37)
    assert utc.isoformat() == "2019-01-20T13:47:24.1219Z"
    assert UtcTime(0, 2019, 1, 20, 13, 47, 29, 0).isoformat() == "2019-01-20T13:47:29Z"
    assert to_jsonable(utc)["iso"] == "2019-01-20T13:47:24.1219Z"
    info = GnssSatInfo(1, 1, 0, 0, 0, (GnssSatellite(0, 5, 40, 13),))
    assert to_jsonable(info)["satellites"] == [{"gnss_id": 0, "sv_id": 5, "cno": 40, "flags": 13}]
    assert to_jsonable((1.0, 2.0)) == [1.0, 2.0]
