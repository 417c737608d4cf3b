"""Device time and packet continuity: SampleTimeFine unwrapping and PacketCounter gaps (reference §2.6).

SampleTimeFine counts 10 kHz ticks and wraps after exactly one day (864e6 ticks) on the
10/100-series incl. the MTi-G-710, after 2**32 ticks on others. GNSS messages carry a time a
few hundred ticks *older* than the inertial message before them, so a step back is not a
wrap: each step is taken as the shortest signed distance modulo the modulus.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import ProtocolError

TICKS_PER_SECOND = 10_000
#: SampleTimeFine modulus of the MTi 10/100-series (MTi-G-710): one day of 10 kHz ticks.
MODULUS_ONE_DAY = 864_000_000
#: SampleTimeFine modulus of the other families (MTi-1, MTi-600).
MODULUS_32_BIT = 1 << 32
COUNTER_MODULUS = 1 << 16
#: Product codes of the 10/100-series (MTi-10/20/30, MTi-100/200/300, MTi-G-700/710): one-day clocks.
_ONE_DAY_FAMILY = re.compile(r"MTi-(?:[1-3]0|[1-3]00|G-7[01]0)(?:\D|$)")


def sample_time_modulus(product_code: str) -> int:
    """SampleTimeFine modulus of the device that says it is ``product_code`` (reference §2.6).

    One day on the 10/100-series, 2**32 on the others (MTi-1 and 600-series): unwrapping a
    600-series clock with the one-day modulus drops every sample above 864e6 ticks and
    restarts the timeline at its wrap. No product code (a device not yet asked, an old
    recording): one day, the MTi-G-710 tankdaq was built for.
    """
    if not product_code or _ONE_DAY_FAMILY.match(product_code):
        return MODULUS_ONE_DAY
    return MODULUS_32_BIT


class SampleTimeUnwrapper:
    """Turns wrapping SampleTimeFine values into a monotonic-through-wraps tick count."""

    def __init__(self, modulus: int = MODULUS_ONE_DAY) -> None:
        self.modulus = modulus
        self.ticks: int | None = None  # unwrapped value of the last update
        self._last_raw = 0

    def _check(self, largest: int, smallest: int) -> None:
        if smallest < 0 or largest >= self.modulus:
            bad = largest if largest >= self.modulus else smallest
            raise ProtocolError(
                f"SampleTimeFine {bad} is outside 0..{self.modulus - 1}: wrong device family modulus? "
                f"(MTi-G-710 and 10/100-series: {MODULUS_ONE_DAY}; MTi-1/600-series: 2**32)"
            )

    def update(self, raw: int) -> int:
        """Unwrapped ticks for one SampleTimeFine value."""
        self._check(raw, raw)
        if self.ticks is None:
            self.ticks = raw
        else:
            step = (raw - self._last_raw) % self.modulus
            if step > self.modulus // 2:
                step -= self.modulus
            self.ticks += step
        self._last_raw = raw
        return self.ticks

    def update_many(self, raw: np.ndarray) -> np.ndarray:
        """Vectorised ``update`` over an array, continuing from the previous call (int64 ticks)."""
        raw = np.asarray(raw, dtype=np.int64)
        if raw.size == 0:
            return np.empty(0, dtype=np.int64)
        self._check(int(raw.max()), int(raw.min()))
        previous = raw[0] if self.ticks is None else self._last_raw
        steps = np.diff(raw, prepend=np.int64(previous)) % self.modulus
        steps[steps > self.modulus // 2] -= self.modulus
        start = int(raw[0]) if self.ticks is None else self.ticks
        ticks = start + np.cumsum(steps)
        self.ticks = int(ticks[-1])
        self._last_raw = int(raw[-1])
        return ticks


class CounterTracker:
    """PacketCounter continuity: gaps modulo 2**16 as (expected, got) pairs, and packets lost.

    A step of more than half the counter range is not a loss but a repeat or reordering
    (counted in ``out_of_order``): the device never skips 32768 packets between two messages.
    """

    def __init__(self) -> None:
        self.gaps: list[tuple[int, int]] = []
        self.lost = 0
        self.out_of_order = 0
        self._last: int | None = None

    @property
    def gap_count(self) -> int:
        """How many times the counter did not advance by exactly one."""
        return len(self.gaps)

    def update(self, counter: int) -> int:
        """Feed one counter value; returns how many packets went missing just before it."""
        return int(self.update_many(np.array([counter]))[0])

    def update_many(self, counters: np.ndarray) -> np.ndarray:
        """Feed counters in arrival order; returns packets missing before each one (0 = contiguous)."""
        counters = np.asarray(counters, dtype=np.int64)
        if counters.size == 0:
            return np.empty(0, dtype=np.int64)
        previous = counters[0] - 1 if self._last is None else self._last
        expected = (np.concatenate(([previous], counters[:-1])) + 1) % COUNTER_MODULUS
        missing = (counters - expected) % COUNTER_MODULUS
        broken = np.flatnonzero(missing)
        self.gaps += list(zip(expected[broken].tolist(), counters[broken].tolist(), strict=True))
        backwards = missing >= COUNTER_MODULUS // 2
        self.out_of_order += int(backwards.sum())
        missing[backwards] = 0
        self.lost += int(missing.sum())
        self._last = int(counters[-1])
        return missing
