"""``tankdaq decode`` on real and synthetic captures: JSON lines, CSV, the summary and one-line errors."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest
from mcap.writer import Writer
from typer.testing import CliRunner

from support.xsens_captures import capture as real_capture
from tankdaq.cli import app
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import decode_mtdata2
from tankdaq.xsens.synthetic import decay_capture

runner = CliRunner()


def test_jsonl_has_one_object_per_message_with_the_decoded_values(tmp_path: Path) -> None:
    capture = real_capture("einride-1")
    out = tmp_path / "out.jsonl"
    result = runner.invoke(app, ["decode", str(capture), "--out", str(out)])
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    framer = StreamFramer()
    frames = framer.feed(capture.read_bytes()) + framer.flush()
    assert len(lines) == len(frames) == 100
    for line, frame in zip(lines, frames, strict=True):
        msg = decode_mtdata2(frame.payload)
        assert set(line) == set(msg)
        assert line["PacketCounter"] == msg["PacketCounter"]
        if "EulerAngles" in msg:
            assert line["EulerAngles"] == list(msg["EulerAngles"])  # degrees, as the device sends them
        assert line["UtcTime"]["iso"] == msg["UtcTime"].isoformat()
    assert "100 MTData2 messages" in result.stderr and "0 counter gaps" in result.stderr


def test_csv_flattens_vectors_with_units(tmp_path: Path) -> None:
    capture = real_capture("einride-2")
    out = tmp_path / "out.csv"
    result = runner.invoke(app, ["decode", str(capture), "--format", "csv", "--out", str(out)])
    assert result.exit_code == 0, result.output
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 100
    first_euler = next(decode_mtdata2(f.payload) for f in StreamFramer().feed(capture.read_bytes())
                       if "EulerAngles" in decode_mtdata2(f.payload))  # fmt: skip
    row = next(r for r in rows if r["EulerAngles.roll_deg"])
    assert float(row["EulerAngles.roll_deg"]) == first_euler["EulerAngles"][0]
    assert {"RateOfTurn.z_rad_s", "Acceleration.x_m_s2", "LatLon.lat_deg", "GnssPvtData.num_sv"} <= set(
        rows[0]
    )


def test_summary_reports_corruption_and_counter_gaps(tmp_path: Path) -> None:
    frames = decay_capture(50)
    damaged = bytearray(frames[: 69 * 10] + frames[69 * 13 :])  # three messages lost
    damaged[69 * 20 + 30] ^= 0xFF  # one bad checksum
    damaged[69 * 21 : 69 * 21] = b"\x01\x02\x03"  # stray bytes after it
    damaged += build_frame(MID.ERROR, b"\x04")
    capture = tmp_path / "damaged.bin"
    capture.write_bytes(bytes(damaged))
    result = runner.invoke(app, ["decode", str(capture)])
    assert result.exit_code == 0
    assert len(result.stdout.splitlines()) == 46
    summary = result.stderr
    assert "46 MTData2 messages" in summary and "1 other frames" in summary and "1 bad checksums" in summary
    assert "2 counter gaps (4 packets lost)" in summary  # the 3 cut out and the one with the bad checksum
    assert "72 skipped bytes" in summary  # the corrupted frame (69) and the 3 stray bytes


def _empty_mcap() -> bytes:
    """A real (empty) MCAP file, as the mcap library writes it."""
    buffer = io.BytesIO()
    writer = Writer(buffer)
    writer.start()
    writer.finish()
    return buffer.getvalue()


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("recording.mcap", _empty_mcap(), "is an MCAP recording, not a raw capture"),
        ("missing.bin", None, "no such raw capture"),
        (".", None, "is a folder"),
        ("empty.bin", b"", "is empty"),
        ("text.txt", b"hello, not a capture", "no Xbus frames"),
    ],
)
@pytest.mark.slow
def test_bad_captures_give_one_line_and_exit_2(
    tmp_path: Path, name: str, content: bytes | None, message: str
) -> None:
    capture = tmp_path / name
    if content is not None:
        capture.write_bytes(content)
    result = runner.invoke(app, ["decode", str(capture)])
    assert result.exit_code == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert "Traceback" not in result.output


def test_unknown_format_is_a_usage_error(tmp_path: Path) -> None:
    capture = tmp_path / "c.bin"
    capture.write_bytes(decay_capture(2))
    result = runner.invoke(app, ["decode", str(capture), "--format", "xml"])
    assert result.exit_code == 2


# Two real legacy MTi-G messages (ethz-asl/ethzasl_xsens_driver issue #66: mode 0x0006, settings 0x1).
LEGACY_PAYLOADS = [
    "3D618499BD2559AD411D13ED3B1B5260BAC11234BB7F213FBE3A38CC3E49C10C"
    "BEA3FCDA3E8BAD87BB5302CB3BF3D3BABF7647E04B33",
    "3DA6C684BD576F7E411D096D3C082A01BC07803C3A6094CBBE3A15783E4A3450"
    "BEA4556A3E8BAE07BB5529D13BF1A408BF7647D54B34",
]


@pytest.fixture
def legacy_capture(tmp_path: Path) -> Path:
    frames = [build_frame(MID.MTDATA, bytes.fromhex(p)) for p in LEGACY_PAYLOADS]
    capture = tmp_path / "legacy.bin"
    capture.write_bytes(frames[0] + build_frame(MID.GOTO_CONFIG_ACK) + frames[1])
    return capture


def test_legacy_mtdata_decodes_with_mode_and_settings(legacy_capture: Path) -> None:
    result = runner.invoke(
        app, ["decode", str(legacy_capture), "--legacy-mode", "0x0006", "--legacy-settings", "1"]
    )
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert [line["PacketCounter"] for line in lines] == [19251, 19252]
    assert set(lines[0]) == {"Acceleration", "RateOfTurn", "MagneticField", "Quaternion", "PacketCounter"}
    assert "2 legacy MTData messages, 1 other frames" in result.stderr


def test_legacy_frames_without_mode_get_a_hint(legacy_capture: Path) -> None:
    result = runner.invoke(app, ["decode", str(legacy_capture)])
    assert result.exit_code == 0 and result.stdout == ""
    assert "2 legacy MTData frames not decoded: give --legacy-mode and --legacy-settings" in result.stderr


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--legacy-mode", "0x0004", "--legacy-settings", "1"], "does not match output mode 0x0004"),
        (["--legacy-mode", "0x0006"], "give both"),
        (["--legacy-mode", "0x8000", "--legacy-settings", "1"], "bits tankdaq does not know"),
        (["--legacy-mode", "six", "--legacy-settings", "1"], "not a number"),
    ],
)
def test_bad_legacy_options_exit_2(legacy_capture: Path, options: list[str], message: str) -> None:
    result = runner.invoke(app, ["decode", str(legacy_capture), *options])
    assert result.exit_code == 2
    assert message in result.stderr
