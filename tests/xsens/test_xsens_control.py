"""Configuration payloads: the reference §3.1 bytes, reply parsers, baud codes and the bandwidth budget."""

from __future__ import annotations

import pytest

from tankdaq.errors import ProtocolError
from tankdaq.xsens.constants import BAUD_CODES, ERROR_NAMES, MID, baud_code
from tankdaq.xsens.control import (
    DECAY_OUTPUTS,
    baudrate_payload,
    check_bandwidth,
    decay_output_configuration,
    device_id_payload,
    frame_bytes_per_second,
    fw_rev_payload,
    output_configuration_payload,
    parse_baudrate,
    parse_device_id,
    parse_error,
    parse_fw_rev,
    parse_output_configuration,
    parse_product_code,
)
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.mtdata2 import encode_mtdata2, make_xdi

DECAY_100HZ = "FA FF C0 18 10 20 FF FF 10 60 FF FF 20 30 00 64 80 20 00 64 40 20 00 64 E0 20 FF FF 13"
DECAY_400HZ = "FA FF C0 18 10 20 FF FF 10 60 FF FF 20 30 01 90 80 20 01 90 40 20 01 90 E0 20 FF FF 8C"


@pytest.mark.parametrize(("rate_hz", "wire"), [(100, DECAY_100HZ), (400, DECAY_400HZ)])
def test_decay_output_configuration_matches_reference_bytes(rate_hz: int, wire: str) -> None:
    entries = decay_output_configuration(rate_hz)
    frame = build_frame(MID.SET_OUTPUT_CONFIGURATION, output_configuration_payload(entries))
    assert frame == bytes.fromhex(wire)
    assert parse_output_configuration(frame[4:-1]) == entries


def test_decay_outputs_and_precision() -> None:
    entries = decay_output_configuration(200, precision="fp1632")
    assert [xdi & 0xFFF0 for xdi, _ in entries] == [make_xdi(n) for n in DECAY_OUTPUTS]
    assert dict(entries)[0x2032] == 200  # EulerAngles in FP16.32
    assert dict(entries)[0x1020] == 0xFFFF
    with pytest.raises(ProtocolError, match=r"1\.\.400"):
        decay_output_configuration(1000)


def test_output_configuration_limits() -> None:
    with pytest.raises(ProtocolError, match="1 to 32"):
        output_configuration_payload([(0x1020, 0xFFFF)] * 33)
    with pytest.raises(ProtocolError, match="16 bits"):
        output_configuration_payload([(0x2030, 70000)])
    with pytest.raises(ProtocolError, match="4-byte"):
        parse_output_configuration(b"\x10\x20\xff")


def test_decay_frame_size_and_bandwidth_from_reference() -> None:
    entries = decay_output_configuration(100)
    # A real decay message: 69 bytes on the wire (reference §3.1).
    payload = encode_mtdata2(
        [
            (0x1020, 1),
            (0x1060, 2),
            (0x2030, (0.0,) * 3),
            (0x8020, (0.0,) * 3),
            (0x4020, (0.0,) * 3),
            (0xE020, 0),
        ]
    )
    assert len(build_frame(MID.MTDATA2, payload)) == 69
    assert frame_bytes_per_second(entries, 100) == 69 * 100
    at_100 = check_bandwidth(entries, 100, 115200)
    assert at_100.bits_per_second == 69_000
    assert at_100.ok and at_100.utilisation == pytest.approx(0.599, abs=1e-3)
    at_400 = check_bandwidth(decay_output_configuration(400), 400, 230400)
    assert at_400.bits_per_second == 276_000 and not at_400.ok
    assert "use at least 460800 baud" in at_400.message()


def test_slower_outputs_add_only_their_own_rate() -> None:
    entries = [(make_xdi("PacketCounter"), 0xFFFF), (make_xdi("LatLon"), 4)]
    assert frame_bytes_per_second(entries, 100) == 5 * 100 + 5 * 100 + (3 + 8) * 4


def test_baud_codes() -> None:
    assert baud_code(921600) == 0x80
    assert baud_code(115200) == 0x02
    assert baudrate_payload(460800) == b"\x00"
    assert BAUD_CODES[0x0A] == BAUD_CODES[0x80] == 921600
    assert all(BAUD_CODES[baud_code(rate)] == rate for rate in BAUD_CODES.values())
    with pytest.raises(ProtocolError, match=r"unsupported baud rate 961200; the MT knows .*115200"):
        baud_code(961200)
    assert parse_baudrate(b"\x80") == 921600
    with pytest.raises(ProtocolError, match="code byte"):
        parse_baudrate(b"\x55")


def test_reply_parsers() -> None:
    assert parse_fw_rev(bytes([1, 2, 3])) == "1.2.3"
    assert parse_fw_rev(bytes([1, 8, 2]) + (45).to_bytes(4, "big") + (71000).to_bytes(4, "big")) == (
        "1.8.2 build 45 scm 71000"
    )
    with pytest.raises(ProtocolError, match="3 or 11"):
        parse_fw_rev(b"\x01\x02")
    assert parse_device_id(bytes.fromhex("01500618")) == 0x01500618
    assert parse_device_id(bytes.fromhex("0000000007780001")) == 0x07780001
    with pytest.raises(ProtocolError, match="4 or 8"):
        parse_device_id(b"\x01\x02\x03")
    assert parse_product_code(b"MTi-G-28A53G35\x00\x00  ") == "MTi-G-28A53G35"
    with pytest.raises(ProtocolError, match="ASCII"):
        parse_product_code(b"\xff\xfe")
    assert parse_error(b"\x04") == (0x04, ERROR_NAMES[0x04])
    assert parse_error(b"\x77")[1] == "unknown device error 0x77"
    with pytest.raises(ProtocolError, match="without an error code"):
        parse_error(b"")


def test_mid_values_named_in_the_interface() -> None:
    assert (MID.WAKEUP, MID.WAKEUP_ACK, MID.GOTO_CONFIG, MID.MTDATA2, MID.ERROR) == (
        0x3E,
        0x3F,
        0x30,
        0x36,
        0x42,
    )
    assert MID.REQ_BAUDRATE == MID.SET_BAUDRATE == 0x18
    assert MID.OUTPUT_CONFIGURATION_ACK == 0xC1 and MID.OUTPUT_SETTINGS_ACK == 0xD3
    assert ERROR_NAMES[0x04] == "message invalid or not implemented"


@pytest.mark.parametrize("text", ["2.4.6", "1.8.2 build 35 scm 0", "1.12.0 build 100 scm 71000"])
def test_a_firmware_revision_payload_reads_back_as_its_text(text: str) -> None:
    assert parse_fw_rev(fw_rev_payload(text)) == text


def test_a_firmware_revision_that_is_not_one_is_refused() -> None:
    with pytest.raises(ProtocolError):
        fw_rev_payload("v1.8")


def test_device_id_payloads_are_4_bytes_or_8_on_a_600_series() -> None:
    assert device_id_payload(0x077B1A2C) == bytes.fromhex("077B1A2C")
    assert parse_device_id(device_id_payload(0x0880_0000_0000_1A2C, family_600=True)) == 0x0880_0000_0000_1A2C
