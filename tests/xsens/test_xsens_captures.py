"""Real MTi-G-710-class captures (einride/xsens-go testdata) decode to exactly their reference decodes."""

from __future__ import annotations

from dataclasses import astuple

import numpy as np
import pytest

from support.xsens_captures import SETS, Field, capture_dir, read_golden_blocks
from tankdaq.xsens.constants import MID
from tankdaq.xsens.control import MAX_FREQUENCY, parse_output_configuration
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import MTData2Message, decode_mtdata2, describe_xdi


def assert_real_equal(got: float, text: str, precision: str, where: str) -> None:
    want = float(text)
    if precision == "float32":
        # the reference prints some float32 values in their shortest float32 form: compare as float32
        assert np.float32(got) == got and np.float32(want) == np.float32(got), where
    else:
        # float64 and fixed point: the reference decodes exactly, so must we (x = raw / 2^20 or 2^32)
        assert got == want, where


def assert_field(msg: MTData2Message, field: Field, where: str) -> None:
    name, frame, precision, lines = field
    assert name in msg, where
    if precision is not None:
        assert msg.precision(name) == precision, where
    if frame is not None:
        assert msg.frame(name) == frame, where
    value = msg[name]
    if name in ("StatusWord", "StatusByte"):
        assert lines == [format(value, "032b" if name == "StatusWord" else "08b")], where
    elif name == "UtcTime":
        assert lines == [value.isoformat()], where
    elif name in ("GnssPvtData", "GnssSatInfo"):
        numbers = [int(line.split(":")[1]) for line in lines]
        assert list(astuple(value))[: len(numbers)] == numbers, where
        assert len(numbers) == (35 if name == "GnssPvtData" else 5), where
    elif precision is None:
        assert lines == [str(value)], where
    else:
        texts = [line.split(":")[-1] for line in lines]
        values = value if isinstance(value, tuple) else (value,)
        assert len(values) == len(texts), where
        for got, text in zip(values, texts, strict=True):
            assert_real_equal(got, text, precision, where)


@pytest.mark.parametrize("name", SETS)
def test_capture_decodes_to_the_golden_values(name: str) -> None:
    path = capture_dir(name)
    framer = StreamFramer()
    frames = framer.feed(path.joinpath("output.bin").read_bytes()) + framer.flush()
    assert (framer.bad_checksums, framer.skipped_bytes, framer.pending) == (0, 0, 0)
    assert [f.mid for f in frames] == [MID.MTDATA2] * 100
    hex_lines = path.joinpath("messages.golden").read_text().split()
    assert [f.to_bytes().hex() for f in frames] == hex_lines
    blocks = read_golden_blocks(path / "output.golden")
    assert len(blocks) == len(frames) == 100
    for index, (frame, block) in enumerate(zip(frames, blocks, strict=True)):
        msg = decode_mtdata2(frame.payload)
        assert msg.unknown_count == 0
        assert sorted(msg) == sorted(field[0] for field in block), f"{name} message {index}"
        for field in block:
            assert_field(msg, field, f"{name} message {index} {field[0]}")


@pytest.mark.parametrize("name", SETS)
def test_output_configuration_matches_golden(name: str) -> None:
    path = capture_dir(name)
    entries = parse_output_configuration(path.joinpath("outputconfig.bin").read_bytes())
    golden = [field for block in read_golden_blocks(path / "outputconfig.golden") for field in block]
    assert len(entries) == len(golden)
    for (xdi, hz), (gname, frame, precision, lines) in zip(entries, golden, strict=True):
        parts = [p for p in (frame, precision) if p is not None]
        assert describe_xdi(xdi) == (f"{gname}({','.join(parts)})" if precision else gname)
        assert lines == (["Max"] if hz == MAX_FREQUENCY else [f"{hz} Hz"])
