"""SampleTimeFine unwrapping (day and 2**32 wraps, GNSS messages with older times) and PacketCounter gaps."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.device.decoding import SampleDecoder
from tankdaq.errors import ProtocolError
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import decode_mtdata2, encode_mtdata2, make_xdi
from tankdaq.xsens.timebase import (
    MODULUS_32_BIT,
    MODULUS_ONE_DAY,
    CounterTracker,
    SampleTimeUnwrapper,
    sample_time_modulus,
)

CAPTURES = Path(__file__).parents[3] / "shared" / "data" / "xsens-captures"


def test_wrap_after_one_day_of_ticks() -> None:
    unwrap = SampleTimeUnwrapper()
    raw = [863_999_800, 863_999_900, 0, 100, 200]
    assert [unwrap.update(r) for r in raw] == [
        863_999_800,
        863_999_900,
        864_000_000,
        864_000_100,
        864_000_200,
    ]


def test_32_bit_family_wraps_at_2_pow_32() -> None:
    unwrap = SampleTimeUnwrapper(modulus=MODULUS_32_BIT)
    assert unwrap.update(2**32 - 50) == 2**32 - 50
    assert unwrap.update(50) == 2**32 + 50
    with pytest.raises(ProtocolError, match="864000000"):
        SampleTimeUnwrapper().update(900_000_000)  # a 2**32 device read with the one-day modulus


def test_gnss_message_with_older_time_is_not_a_wrap() -> None:
    # Inertial messages every 100 ticks; a GNSS message 480 ticks older than the one before it.
    raw = [1000, 1100, 1200, 720, 1300, 1400]
    unwrap = SampleTimeUnwrapper()
    assert [unwrap.update(r) for r in raw] == raw
    # the same right at the wrap: the older GNSS time sits before the wrap point
    raw = [863_999_900, 0, 863_999_600, 100, 200]
    unwrap = SampleTimeUnwrapper()
    assert [unwrap.update(r) for r in raw] == [
        863_999_900,
        864_000_000,
        863_999_600,
        864_000_100,
        864_000_200,
    ]


def test_real_captures_with_gnss_messages_unwrap_to_themselves() -> None:
    path = CAPTURES / "einride-1" / "output.bin"
    if not path.is_file():
        pytest.skip(f"real captures not found at {path}")
    times = [decode_mtdata2(f.payload)["SampleTimeFine"] for f in StreamFramer().feed(path.read_bytes())]
    assert any(np.diff(times) < 0)  # the capture does step back
    assert SampleTimeUnwrapper().update_many(np.array(times)).tolist() == times


@settings(max_examples=100, deadline=None)
@given(
    st.integers(0, MODULUS_ONE_DAY - 1),
    st.lists(st.integers(-600, 50_000), min_size=1, max_size=200),
    st.lists(st.integers(1, 50), max_size=8),
)
@pytest.mark.slow
def test_vectorised_unwrap_equals_scalar_and_recovers_the_true_time(
    start: int, steps: list[int], chunk_sizes: list[int]
) -> None:
    true_ticks = start + np.cumsum([0, *steps])
    raw = true_ticks % MODULUS_ONE_DAY
    scalar = SampleTimeUnwrapper()
    assert [scalar.update(int(r)) for r in raw] == true_ticks.tolist()
    vector = SampleTimeUnwrapper()
    pieces, pos = [], 0
    for size in [*chunk_sizes, len(raw)]:
        pieces.append(vector.update_many(raw[pos : pos + size]))
        pos += size
    assert np.concatenate(pieces).tolist() == true_ticks.tolist()


def test_counter_gaps_modulo_2_pow_16() -> None:
    tracker = CounterTracker()
    counters = [65533, 65534, 65535, 0, 1, 4, 5, 5000, 5000]
    missing = [tracker.update(c) for c in counters[:7]]
    assert missing == [0, 0, 0, 0, 0, 2, 0]
    assert tracker.gaps == [(2, 4)] and tracker.lost == 2
    tracker.update_many(np.array(counters[7:]))
    assert tracker.gaps == [(2, 4), (6, 5000), (5001, 5000)]
    assert tracker.lost == 2 + 4994 and tracker.out_of_order == 1  # the repeat is not a loss


@pytest.mark.slow
def test_counter_tracker_vectorised_equals_scalar() -> None:
    rng = np.random.default_rng(7)
    counters = (np.cumsum(rng.choice([1, 1, 1, 2, 5], size=5000)) + 60000) % 65536
    scalar, vector = CounterTracker(), CounterTracker()
    one_by_one = [scalar.update(int(c)) for c in counters]
    in_blocks = np.concatenate([vector.update_many(part) for part in np.array_split(counters, 7)])
    assert one_by_one == in_blocks.tolist()
    assert scalar.gaps == vector.gaps and scalar.lost == vector.lost == int(
        np.sum(np.diff(counters) % 65536 - 1)
    )


@pytest.mark.parametrize(
    ("product_code", "modulus"),
    [
        ("MTi-630-2A8G4", MODULUS_32_BIT),
        ("MTi-680G-2A8G4", MODULUS_32_BIT),
        ("MTi-1-8A7G6", MODULUS_32_BIT),
        ("MTi-G-710-2A8G4", MODULUS_ONE_DAY),
        ("MTi-300-2A8G4", MODULUS_ONE_DAY),
        ("MTi-10-2A5G4", MODULUS_ONE_DAY),
        ("", MODULUS_ONE_DAY),  # not yet asked: the MTi-G-710's
    ],
)
def test_modulus_follows_the_device_family(product_code: str, modulus: int) -> None:
    assert sample_time_modulus(product_code) == modulus


def _mtdata2(counter: int, ticks: int) -> bytes:
    items = [(make_xdi("PacketCounter"), counter), (make_xdi("SampleTimeFine"), ticks),
             (make_xdi("EulerAngles"), (1.0, 2.0, 3.0))]  # fmt: skip
    return build_frame(MID.MTDATA2, encode_mtdata2(items))


@settings(max_examples=15, deadline=None)
@given(cuts=st.lists(st.integers(1, 40 * 19), min_size=1, max_size=6))
def test_600_series_decoder_unwraps_its_clock_and_counter_across_blocks(cuts: list[int]) -> None:
    # a 600-series stream whose SampleTimeFine and PacketCounter both wrap, cut into arbitrary reads
    n = 40
    raw_ticks = [(2**32 - 2_000 + 100 * k) % 2**32 for k in range(n)]
    counters = [(65_530 + k) % 65_536 for k in range(n)]
    stream = b"".join(_mtdata2(c, t) for c, t in zip(counters, raw_ticks, strict=True))
    decoder = SampleDecoder.for_device("MTi-630-2A8G4")
    tracker = CounterTracker()
    bounds = [0, *sorted(set(cuts)), len(stream)]
    blocks = [decoder.feed(stream[a:b], 0.0)[0] for a, b in itertools.pairwise(bounds)]
    samples = np.concatenate([*blocks, decoder.feed(b"", 0.0)[0]])
    assert samples["ticks"].tolist() == [2**32 - 2_000 + 100 * k for k in range(n)]
    assert samples["counter"].tolist() == counters
    tracker.update_many(samples["counter"])
    assert (tracker.lost, tracker.gap_count) == (0, 0)


def test_counter_wrap_is_not_a_loss_and_a_loss_at_the_wrap_is_counted() -> None:
    tracker = CounterTracker()
    assert tracker.update_many(np.array([65_533, 65_534])).tolist() == [0, 0]
    assert tracker.update_many(np.array([65_535, 0, 1])).tolist() == [0, 0, 0]  # the wrap, across calls
    assert (tracker.lost, tracker.gap_count, tracker.out_of_order) == (0, 0, 0)
    tracker.update(65_535)  # a repeat, not 65534 lost packets
    assert (tracker.lost, tracker.out_of_order) == (0, 1)
    assert tracker.update_many(np.array([1])).tolist() == [1]  # 0 went missing at the wrap
    assert (tracker.lost, tracker.gaps[-1]) == (1, (0, 1))
