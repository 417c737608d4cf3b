"""Decoders never raise on bytes: structured random MTData2 and legacy messages, not only random bytes.

Random bytes rarely get past the checksum; these messages do. Each is a valid frame of items
with identifiers tankdaq knows (any precision and frame bits), random payloads and sizes that
are sometimes right and sometimes not, zero-filled times as a GNSS device sends before a fix.
Whatever the items hold, the stream decoder, the per-message decoder and every consumer of a
decoded value (JSON, the decode command's CSV columns, samples) either succeed or refuse with a
ProtocolError, never another exception.
"""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.cli.decode import flatten
from tankdaq.device.decoding import SampleDecoder
from tankdaq.device.legacy_output import LegacyOutput
from tankdaq.errors import ProtocolError
from tankdaq.xsens.column_decoder import DecodedBlock
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.legacy import MODE_ORIENTATION, decode_mtdata, legacy_layout
from tankdaq.xsens.mtdata2 import (
    DATA_SPECS,
    TYPE_MASK,
    UTC_STRUCT,
    UtcTime,
    decode_mtdata2,
    item_size,
    to_jsonable,
)

#: Zero-filled UtcTime as a GNSS receiver sends it before its first fix, and other non-times.
NOT_A_TIME = [
    UtcTime(0, 0, 0, 0, 0, 0, 0, 0),
    UtcTime(0, 2024, 2, 30, 12, 0, 0, 0),
    UtcTime(0, 2024, 13, 1, 0, 0, 0, 0x04),
    UtcTime(2_000_000_000, 2024, 1, 1, 25, 61, 99, 0x04),
]


@st.composite
def items(draw: st.DrawFn) -> bytes:
    """One MTData2 item: a known identifier with any format bits, a payload of any size."""
    spec = draw(st.sampled_from(DATA_SPECS))
    xdi = (spec.base & TYPE_MASK) | draw(st.integers(0, 0xF))
    expected = item_size(spec, xdi)
    if spec.kind == "utc" and draw(st.booleans()):
        payload = UTC_STRUCT.pack(*draw(st.sampled_from(NOT_A_TIME)).__dict__.values())
    elif expected is not None and draw(st.booleans()):
        payload = draw(st.binary(min_size=expected, max_size=expected))
    else:
        payload = draw(st.binary(max_size=60))
    return xdi.to_bytes(2, "big") + bytes([len(payload)]) + payload


messages = st.lists(items(), min_size=1, max_size=8).map(b"".join)


def _consume(message: object) -> None:
    """Everything a command does with a decoded message: JSON, CSV columns."""
    for name, value in message.items():  # type: ignore[attr-defined]
        json.dumps(to_jsonable(value))
        flatten(name, value)


@settings(max_examples=400, deadline=None)
@given(st.lists(messages, min_size=1, max_size=6))
@pytest.mark.slow
def test_structured_random_mtdata2_never_raises(payloads: list[bytes]) -> None:
    stream = b"".join(build_frame(MID.MTDATA2, payload) for payload in payloads)
    for payload in payloads:
        try:
            message = decode_mtdata2(payload)
        except ProtocolError:
            continue  # sizes that do not fit the identifier are refused on purpose
        _consume(message)
    decoder = SampleDecoder()
    fed = decoder.feed(stream, 0.0)  # the driver's and replay's path ...
    quiet = decoder.feed(b"", 0.0)  # ... where a quiet line confirms the last frame
    block = DecodedBlock.concat([fed[1], quiet[1]])
    assert block.frames == len(payloads) and block.bad_checksums == 0
    assert fed[0].size + quiet[0].size <= block.n_messages
    for message in block.messages():
        _consume(message)


@pytest.mark.parametrize("utc", NOT_A_TIME)
def test_a_time_that_is_not_a_time_is_kept_as_invalid(utc: UtcTime) -> None:
    assert not utc.valid and utc.isoformat() is None
    assert to_jsonable(utc)["valid"] is False and to_jsonable(utc)["iso"] is None
    assert flatten("UtcTime", utc)["UtcTime"] is None


def test_a_leap_second_is_a_valid_time() -> None:
    utc = UtcTime(500_000_000, 2016, 12, 31, 23, 59, 60, 0x04)
    assert utc.valid and utc.isoformat() == "2016-12-31T23:59:60.5Z"


#: Legacy layout with a UTC timestamp block (output settings timestamp field = 2).
LEGACY_UTC = (MODE_ORIENTATION, 0x00000002)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=80), st.sampled_from(NOT_A_TIME))
@pytest.mark.slow
def test_legacy_messages_with_any_bytes_or_a_zero_time_never_raise(noise: bytes, utc: UtcTime) -> None:
    layout = legacy_layout(*LEGACY_UTC)
    size = layout.length
    zero_time = (noise + bytes(size))[: size - UTC_STRUCT.size] + UTC_STRUCT.pack(*utc.__dict__.values())
    for payload in (noise, zero_time):
        try:
            message = decode_mtdata(payload, *LEGACY_UTC)
        except ProtocolError:
            continue
        _consume(message)
        if payload is zero_time:
            assert message["UtcTime"].valid is False
    decoder = SampleDecoder(LegacyOutput.for_decay(100.0))
    decoder.feed(build_frame(MID.MTDATA, noise) + build_frame(MID.MTDATA, zero_time), 0.0)
