"""Legacy MTi-G (Mark III) MTData: layouts, the public ethz issue #66 messages, and round trips."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.errors import ProtocolError
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame, parse_frame
from tankdaq.xsens.legacy import (
    MODE_AUXILIARY,
    MODE_CALIBRATED,
    MODE_ORIENTATION,
    MODE_POSITION,
    MODE_RAW_GPS,
    MODE_RAW_INERTIAL,
    MODE_STATUS,
    MODE_TEMPERATURE,
    MODE_VELOCITY,
    NED_BIT,
    RawGps,
    decode_mtdata,
    encode_mtdata,
    legacy_layout,
    parse_configuration,
)
from tankdaq.xsens.mtdata2 import FP1220_SCALE, FP1632_SCALE, UtcTime

# ethz-asl/ethzasl_xsens_driver issue #66: an MTi-G-28A53G35 (DID 0x01500618) at mode 0x0006,
# settings 0x00000001 (calibrated + quaternion + sample counter, float32): two consecutive messages.
ISSUE_66 = [
    "3D 61 84 99 BD 25 59 AD 41 1D 13 ED 3B 1B 52 60 BA C1 12 34 BB 7F 21 3F BE 3A 38 CC 3E 49 C1 0C"
    " BE A3 FC DA 3E 8B AD 87 BB 53 02 CB 3B F3 D3 BA BF 76 47 E0 4B 33",
    "3D A6 C6 84 BD 57 6F 7E 41 1D 09 6D 3C 08 2A 01 BC 07 80 3C 3A 60 94 CB BE 3A 15 78 3E 4A 34 50"
    " BE A4 55 6A 3E 8B AE 07 BB 55 29 D1 3B F1 A4 08 BF 76 47 D5 4B 34",
]


def test_issue_66_messages() -> None:
    layout = legacy_layout(0x0006, 0x00000001)
    assert layout.length == 54  # the data length the device reported
    assert [b.name for b in layout.blocks] == [
        "Acceleration", "RateOfTurn", "MagneticField", "Quaternion", "PacketCounter"
    ]  # fmt: skip
    decoded = [decode_mtdata(bytes.fromhex(hex_), 0x0006, 0x1) for hex_ in ISSUE_66]
    assert [m["PacketCounter"] for m in decoded] == [19251, 19252]
    for msg, hex_ in zip(decoded, ISSUE_66, strict=True):
        assert math.hypot(*msg["Acceleration"]) == pytest.approx(9.81, abs=0.01)  # at rest: gravity only
        assert math.hypot(*msg["Quaternion"]) == pytest.approx(1.0, abs=1e-5)  # a unit quaternion
        assert max(abs(w) for w in msg["RateOfTurn"]) < 0.01  # rad/s, the sensor sat still
        assert msg.precision("Quaternion") == "float32" and msg.frame("Quaternion") == "ENU"
        assert encode_mtdata(msg, 0x0006, 0x1) == bytes.fromhex(hex_)
    frame = build_frame(MID.MTDATA, bytes.fromhex(ISSUE_66[0]))
    assert frame[:4] == bytes.fromhex("FA FF 32 36") and parse_frame(frame).payload == bytes.fromhex(
        ISSUE_66[0]
    )


def test_configuration_reply_of_a_legacy_mti_g() -> None:
    # Configuration as issue #66 reports it (master/device id, period 1152, 54 data bytes, mode, settings);
    # bytes the issue does not show are zero.
    payload = bytearray(118)
    payload[0:6] = bytes.fromhex("01500618 0480")
    payload[96:110] = bytes.fromhex("0001 01500618 0036 0006 00000001")
    config = parse_configuration(bytes(payload))
    assert (config.master_id, config.device_id, config.period, config.num_devices) == (
        0x01500618,
        0x01500618,
        1152,
        1,
    )
    assert (config.data_length, config.output_mode, config.output_settings) == (54, 0x0006, 0x1)
    assert config.sample_rate_hz == 100.0 and config.is_legacy_output
    assert legacy_layout(config.output_mode, config.output_settings).length == config.data_length
    with pytest.raises(ProtocolError, match="118"):
        parse_configuration(bytes(31))


def test_configuration_of_a_mark_iv_device_is_not_legacy() -> None:
    # MTi-30 reply from ethz issue #94 (zeros where the issue shows zeros).
    payload = (
        bytes.fromhex("0368248C 0480")
        + bytes(90)
        + bytes.fromhex("0001 0368248C 0000 0000 00000000 00 27 01 07 02 49 05 01")
    )
    config = parse_configuration(payload)
    assert config.device_id == 0x0368248C and not config.is_legacy_output


def test_block_order_and_sizes_for_every_block() -> None:
    mode = (MODE_RAW_INERTIAL | MODE_RAW_GPS | MODE_TEMPERATURE | MODE_CALIBRATED | MODE_ORIENTATION
            | MODE_AUXILIARY | MODE_POSITION | MODE_VELOCITY | MODE_STATUS)  # fmt: skip
    layout = legacy_layout(mode, 0x4 | 0x2)  # Euler, UTC
    assert [b.name for b in layout.blocks] == [
        "RawAccGyrMagTemp", "RawGpsPressure", "Temperature", "Acceleration", "RateOfTurn", "MagneticField",
        "EulerAngles", "AnalogIn1", "AnalogIn2", "LatLon", "AltitudeEllipsoid", "VelocityXYZ", "StatusByte",
        "UtcTime",
    ]  # fmt: skip
    assert layout.length == 20 + 44 + 4 + 36 + 12 + 4 + 12 + 12 + 1 + 12
    fp = legacy_layout(MODE_CALIBRATED | MODE_ORIENTATION, 0x8 | 0x0200 | 0x0040)  # matrix, FP16.32, no mag
    assert [b.name for b in fp.blocks] == ["Acceleration", "RateOfTurn", "RotationMatrix"]
    assert fp.length == (3 + 3 + 9) * 6
    assert legacy_layout(MODE_AUXILIARY, 0x0400).blocks[0].name == "AnalogIn2"


@pytest.mark.parametrize(
    ("mode", "settings_", "match"),
    [
        (0x8000, 0, "bits"),
        (MODE_ORIENTATION, 0x3, "timestamp"),
        (MODE_ORIENTATION, 0x0300, "precision"),
        (MODE_ORIENTATION, 0xC, "orientation"),
        (MODE_POSITION, 0x4000, "LLA"),
    ],
)
def test_impossible_layouts_are_refused(mode: int, settings_: int, match: str) -> None:
    with pytest.raises(ProtocolError, match=match):
        legacy_layout(mode, settings_)


def test_wrong_message_length_says_what_to_do() -> None:
    with pytest.raises(ProtocolError, match="re-read the device configuration"):
        decode_mtdata(bytes(50), 0x0006, 0x1)
    with pytest.raises(ProtocolError, match="needs values for Quaternion"):
        encode_mtdata({"PacketCounter": 1}, MODE_ORIENTATION, 0x1)


# ---------------------------------------------------------------------------------- round trips

PRECISION_SETTINGS = {
    0x000: st.floats(-1e6, 1e6, width=32),
    0x100: st.integers(-(2**31), 2**31 - 1).map(lambda raw: raw / FP1220_SCALE),
    0x200: st.integers(-(2**47), 2**47 - 1).map(lambda raw: raw / FP1632_SCALE),
}
u16 = st.integers(0, 0xFFFF)


@st.composite
def legacy_messages(draw: st.DrawFn) -> tuple[int, int, dict[str, object]]:
    mode = draw(st.integers(0, 0x7FFF)) & (0x003F | MODE_STATUS | MODE_RAW_GPS | MODE_RAW_INERTIAL)
    precision = draw(st.sampled_from(sorted(PRECISION_SETTINGS)))
    timestamp = draw(st.sampled_from([0, 1, 2]))
    orientation = draw(st.sampled_from([0x0, 0x4, 0x8]))
    disabled = draw(st.integers(0, 0x7)) << 4 | draw(st.integers(0, 3)) << 10
    settings_ = timestamp | orientation | precision | disabled | draw(st.sampled_from([0, NED_BIT]))
    reals = PRECISION_SETTINGS[precision]
    values: dict[str, object] = {}
    for block in legacy_layout(mode, settings_).blocks:
        if block.kind == "reals":
            drawn = tuple(draw(reals) for _ in range(block.count))
            values[block.name] = drawn[0] if block.count == 1 else drawn
        elif block.kind == "utc":
            values[block.name] = draw(
                st.builds(UtcTime, st.integers(0, 999_999_999), u16, *[st.integers(0, 255)] * 6)
            )
        elif block.kind == "rawgps":
            i32, u32 = st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1)
            fields = [u16, st.integers(0, 255), u32, *[i32] * 6, *[u32] * 3, st.integers(0, 255)]
            values[block.name] = draw(st.builds(RawGps, *fields))
        elif block.name == "RawAccGyrMagTemp":
            values[block.name] = tuple(draw(u16) for _ in range(10))
        else:
            values[block.name] = draw(st.integers(0, 0xFF if block.name == "StatusByte" else 0xFFFF))
    return mode, settings_, values


@settings(max_examples=200, deadline=None)
@given(legacy_messages())
@pytest.mark.slow
def test_legacy_round_trip(case: tuple[int, int, dict[str, object]]) -> None:
    mode, settings_, values = case
    payload = encode_mtdata(values, mode, settings_)
    assert len(payload) == legacy_layout(mode, settings_).length
    decoded = decode_mtdata(payload, mode, settings_)
    assert dict(decoded) == values
    if "EulerAngles" in decoded:
        assert decoded.frame("EulerAngles") == ("NED" if settings_ & NED_BIT else "ENU")
