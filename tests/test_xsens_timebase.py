"""SampleTimeFine unwrapping (day wrap, GNSS messages with older times) and PacketCounter gaps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.errors import ProtocolError
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import decode_mtdata2
from tankdaq.xsens.timebase import MODULUS_32_BIT, MODULUS_ONE_DAY, CounterTracker, SampleTimeUnwrapper

CAPTURES = Path(__file__).parents[2] / "shared" / "data" / "xsens-captures"


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
