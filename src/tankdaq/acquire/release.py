"""Release detection: when did the engineer let go, and when has the model come to rest?

A streaming state machine on the samples of one axis:

    still -> tilted -> held (away from rest, rate small) -> leaving (moving back fast)
          -> released (confirmed once the model swings through its rest angle) -> settled

Two questions are kept apart. *Whether* the model was released is decided late and safely:
the angle must swing through the still-water angle, which a hand putting the model back does
not do, and hand tremor cannot. *When* it was released is then found looking back: the release
is the instant the held motion (swaying or trembling: the rate at release need not be zero) stops
explaining the data and the restoring moment takes over, i.e. where the angular acceleration
jumps. A cubic in time (a still hand), or a cubic spline where the hand sways, before the instant
and the decay equation after it, sharing the state at the instant, are fitted jointly to angle and
rate over three quarter cycles, and the instant is scanned; the event carries its 95 % interval. Right after
release the motion is tiny against the noise; the later swing, run back through the
equation, pins the start down. The event reports the first sample of free motion, not the
sample at which the detector became sure (about 3/4 of a period later).

Everything is vectorised per state (the machine jumps from transition to transition through
numpy searches), so an hour of samples is scanned in about a second, offline or fed in blocks.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from ..errors import InputError
from ..ident.base import EstimatorMixin
from ..records import DecayEnd
from ..samples import AXIS_FIELDS
from .release_instant import find_release_instant

STILL, TILTED, HELD, LEAVING, SWUNG, DECAYING = "still", "tilted", "held", "leaving", "swung", "decaying"
UNKNOWN = "unknown"

#: Away from the still water by more than this (deg) the model is tilted (``tilt_min_deg``'s default): less is
#: the water, a hand's touch or a bump, never a tilt for a decay.
TILT_MIN_DEG = 1.5


class ReleaseKind(StrEnum):
    """What the detector saw (``ReleaseEvent.kind``)."""

    HELD = "held"
    RELEASED = "released"
    PUT_BACK = "put_back"
    SETTLED = "settled"


@dataclass(frozen=True)
class ReleaseEvent:
    """Something the detector saw. ``index`` counts samples from the first one fed.

    ``held``: the model is held away from rest (``angle_rad`` the held angle).
    ``released``: ``index`` is the first sample of free motion, ``release_t`` the estimated
    instant on the device clock (after the last held sample, at or before the first free one),
    ``release_se_s`` its standard error (s), ``release_u95_s`` the half-width of its 95 % interval (s; NaN:
    unknown), ``angle_rad``/``rate_rad_s`` the initial state.
    ``put_back``: a hold ended without a release. ``settled``: the amplitude stayed below the
    threshold for a window (``ended`` ``DecayEnd.SETTLED``) or the decay timed out (``TIMEOUT``);
    ``settle_s`` is the time from release.
    Every event also carries ``confirmed_index`` and ``confirmed_t``: the sample at which the detector
    decided, and its time on the device clock (where the data, not a read's timing, ends a decay).
    """

    kind: ReleaseKind
    index: int
    t: float
    confirmed_index: int
    angle_rad: float = math.nan
    rate_rad_s: float = math.nan
    baseline_rad: float = math.nan
    release_t: float = math.nan
    release_se_s: float = math.nan
    release_u95_s: float = math.nan
    settle_s: float = math.nan
    ended: DecayEnd | None = None
    confirmed_t: float = math.nan


def _first_sustained(mask: np.ndarray, length: int, start: int) -> int | None:
    """First index j >= start such that mask[j-length+1 .. j] is all true (None if none yet)."""
    if length <= 1:
        hits = np.flatnonzero(mask[start:])
        return int(start + hits[0]) if hits.size else None
    counts = np.concatenate(([0], np.cumsum(mask, dtype=np.int64)))
    ends = np.arange(max(start, length - 1), mask.size)
    full = counts[ends + 1] - counts[ends + 1 - length] == length
    hits = np.flatnonzero(full)
    return int(ends[hits[0]]) if hits.size else None


def _first(mask: np.ndarray, start: int) -> int | None:
    hits = np.flatnonzero(mask[start:])
    return int(start + hits[0]) if hits.size else None


def _fill_gaps(values: np.ndarray, before: float) -> np.ndarray:
    """Carry the last finite value over NaN (a message without that output) so indices stay put;
    ``before`` stands in for a NaN at the very start."""
    finite = np.isfinite(values)
    if finite.all():
        return values
    filled = values.copy()
    last_index = np.maximum.accumulate(np.where(finite, np.arange(values.size), -1))
    filled[last_index >= 0] = values[last_index[last_index >= 0]]
    filled[last_index < 0] = before
    return filled


def _trailing_mean(values: np.ndarray, width: int) -> np.ndarray:
    """Causal moving average (shorter at the start)."""
    sums = np.cumsum(np.concatenate(([0.0], values)))
    idx = np.arange(values.size)
    lo = np.maximum(idx + 1 - width, 0)
    return (sums[idx + 1] - sums[lo]) / (idx + 1 - lo)


class ReleaseDetector(EstimatorMixin):
    """Streaming release/settle detector for one axis (scikit-learn style settings, results in ``_``).

    Angles and rates in the samples are rad and rad/s; thresholds are given in degrees because
    people set them. ``settle_deg`` 0.5 follows ITTC (record until the amplitude is below 0.5 deg).
    ``keep_events`` False: ``events_`` stays empty and ``feed`` only returns the new events (a detector
    fed for a whole lab day need not keep every event it saw).
    """

    def __init__(
        self,
        axis: str = "roll",
        rate_hz: float | None = None,
        tilt_min_deg: float = TILT_MIN_DEG,
        hold_rate_max_deg_s: float = 3.0,
        hold_min_s: float = 0.5,
        leave_rate_deg_s: float = 3.0,
        swing_through_deg: float = 0.3,
        confirm_timeout_s: float = 5.0,
        settle_deg: float = 0.5,
        settle_window_s: float = 3.0,
        decay_timeout_s: float = 120.0,
        smooth_s: float = 0.05,
        fit_before_s: float = 0.6,
        scan_back_s: float = 0.4,
        fit_quarters: float = 3.0,
        still_mean_s: float = 5.0,
        keep_events: bool = True,
    ) -> None:
        if axis not in AXIS_FIELDS:
            raise InputError(f"axis {axis!r} not understood; use {' or '.join(AXIS_FIELDS)} (or auto)")
        self.axis = axis
        self.rate_hz = rate_hz
        self.tilt_min_deg = tilt_min_deg
        self.hold_rate_max_deg_s = hold_rate_max_deg_s
        self.hold_min_s = hold_min_s
        self.leave_rate_deg_s = leave_rate_deg_s
        self.swing_through_deg = swing_through_deg
        self.confirm_timeout_s = confirm_timeout_s
        self.settle_deg = settle_deg
        self.settle_window_s = settle_window_s
        self.decay_timeout_s = decay_timeout_s
        self.smooth_s = smooth_s
        self.fit_before_s = fit_before_s
        self.scan_back_s = scan_back_s
        self.fit_quarters = fit_quarters
        self.still_mean_s = still_mean_s
        self.keep_events = keep_events
        self.reset()

    def reset(self) -> ReleaseDetector:
        """Forget everything fed so far."""
        self.state_ = UNKNOWN
        self.rate_hz_: float | None = self.rate_hz  # as given, or learnt from the samples fed
        self.events_: list[ReleaseEvent] = []
        self.baseline_rad_: float = math.nan
        self.samples_seen_ = 0
        self._t = np.empty(0)
        self._x = np.empty(0)
        self._r = np.empty(0)
        self._first = 0  # global index of the buffer's first sample
        self._pos = 0  # global index of the next sample to examine
        self._hold_angle = math.nan
        self._leave_index = 0
        self._swung_index = 0
        self._last_finite = [0.0, 0.0]  # angle, rate: what a NaN at the very start is read as
        self._release: ReleaseEvent | None = None
        return self

    # ---- feeding ----------------------------------------

    def feed(self, samples: np.ndarray) -> list[ReleaseEvent]:
        """Feed a block of ``SAMPLE_DTYPE`` samples; return the events it completed."""
        angle_field, rate_field = AXIS_FIELDS[self.axis]
        return self.feed_arrays(samples["t"], samples[angle_field], samples[rate_field])

    def feed_arrays(self, t: np.ndarray, angle: np.ndarray, rate: np.ndarray) -> list[ReleaseEvent]:
        """Feed device time (s), angle (rad) and rate (rad/s) of the axis; return new events."""
        t, angle, rate = (np.asarray(a, dtype=float) for a in (t, angle, rate))
        if not t.shape == angle.shape == rate.shape:
            raise InputError("time, angle and rate blocks have different lengths")
        before = len(self.events_)
        # Long arrays go in pieces: the history stays short, so every search is over a few seconds.
        for start in range(0, t.size, self.piece):
            piece = slice(start, start + self.piece)
            self._feed_piece(t[piece], angle[piece], rate[piece])
        new = self.events_[before:]
        if not self.keep_events:  # a live detector: only what is returned (a lab day kept 1 MB of them)
            del self.events_[before:]
        return new

    piece = 16384

    def _feed_piece(self, t: np.ndarray, angle: np.ndarray, rate: np.ndarray) -> None:
        angle, rate = _fill_gaps(angle, self._last_finite[0]), _fill_gaps(rate, self._last_finite[1])
        if t.size:
            self._last_finite = [float(angle[-1]), float(rate[-1])]
        self._t = np.concatenate((self._t, t))
        self._x = np.concatenate((self._x, angle))
        self._r = np.concatenate((self._r, rate))
        self.samples_seen_ += t.size
        if self.rate_hz_ is None and self._t.size > 10:
            self.rate_hz_ = float(1.0 / np.median(np.diff(self._t)))
        if self.rate_hz_ is None:
            return
        steps: dict[str, Callable[[], bool]] = {
            UNKNOWN: self._step_unknown,
            STILL: self._step_still,
            TILTED: self._step_tilted,
            HELD: self._step_held,
            LEAVING: self._step_leaving,
            SWUNG: self._step_swung,
            DECAYING: self._step_decaying,
        }
        self._derive()
        while steps[self.state_]():
            pass
        self._trim()

    def fit(self, samples: np.ndarray) -> ReleaseDetector:
        """Offline: run over a whole array (from a fresh state); events in ``events_``."""
        self.reset()
        self.feed(samples)
        return self

    # ---- derived signals over the buffer ----------------------------------------

    def _n(self, seconds: float) -> int:
        return max(1, round(seconds * float(self.rate_hz_ or 1.0)))

    def _derive(self) -> None:
        self._smooth = _trailing_mean(self._r, self._n(self.smooth_s))
        self._calm = np.abs(self._smooth) < math.radians(self.hold_rate_max_deg_s)

    def _local(self, index: int) -> int:
        return index - self._first

    def _offset(self) -> np.ndarray:
        return self._x - self.baseline_rad_

    def _emit(
        self,
        kind: ReleaseKind,
        local: int,
        confirmed_local: int,
        *,
        angle_rad: float = math.nan,
        rate_rad_s: float = math.nan,
        release_t: float = math.nan,
        release_se_s: float = math.nan,
        release_u95_s: float = math.nan,
        settle_s: float = math.nan,
        ended: DecayEnd | None = None,
    ) -> ReleaseEvent:
        event = ReleaseEvent(
            kind,
            local + self._first,
            float(self._t[local]),
            confirmed_local + self._first,
            angle_rad=angle_rad,
            rate_rad_s=rate_rad_s,
            baseline_rad=self.baseline_rad_,
            release_t=release_t,
            release_se_s=release_se_s,
            release_u95_s=release_u95_s,
            settle_s=settle_s,
            ended=ended,
            confirmed_t=float(self._t[confirmed_local]),
        )
        self.events_.append(event)
        return event

    def _go(self, state: str, local: int) -> bool:
        self.state_ = state
        self._pos = local + self._first
        return True

    def _wait(self) -> bool:
        self._pos = self._first + self._t.size
        return False

    def _trim(self) -> None:
        """Drop history no state can look back to (the release fit reaches at most a few s back)."""
        reach_s = max(self.settle_window_s, self.still_mean_s, self.fit_before_s + self.confirm_timeout_s)
        keep_s = max(10.0, reach_s + 1.0)
        cut = self._t.size - self._n(keep_s)
        if self.state_ in (LEAVING, SWUNG):
            cut = min(cut, self._local(self._leave_index) - self._n(self.fit_before_s) - 1)
        if cut > 0:
            self._t, self._x, self._r = self._t[cut:], self._x[cut:], self._r[cut:]
            self._first += cut

    # ---- states ----------------------------------------

    def _step_unknown(self) -> bool:
        """Learn the still-water angle from the first calm stretch (a model held at start: level 0)."""
        n = self._n(1.0)
        j = _first_sustained(self._calm, n, self._local(self._pos))
        if j is None:
            return self._wait()
        level = float(np.mean(self._x[j - n + 1 : j + 1]))
        if abs(level) < math.radians(self.tilt_min_deg):
            self.baseline_rad_ = level
            return self._go(STILL, j)
        self.baseline_rad_ = 0.0
        self._hold_angle = level
        self._emit(ReleaseKind.HELD, j, j, angle_rad=level)
        return self._go(HELD, j)

    def _step_still(self) -> bool:
        j = _first(np.abs(self._offset()) > math.radians(self.tilt_min_deg), self._local(self._pos))
        if j is None:
            return self._wait()
        self._refine_baseline(j)
        return self._go(TILTED, j)

    def _refine_baseline(self, tilt: int) -> None:
        """Re-read the still-water angle from the calm water just before the tilt.

        The angle learnt when the last decay settled is the mean of a window that starts at a
        peak of the dying oscillation, a few hundredths of a degree off; the initial angle of the
        coming release is measured from this one. Kept only if that stretch is truly still.
        """
        lo, hi = tilt - self._n(self.still_mean_s), tilt - self._n(1.0)
        if lo < 0:
            return
        quiet = np.abs(self._offset()[lo:hi]) < math.radians(self.settle_deg)
        if np.all(quiet & self._calm[lo:hi]):
            self.baseline_rad_ = float(np.mean(self._x[lo:hi]))

    def _step_tilted(self) -> bool:
        n = self._n(self.hold_min_s)
        away = np.abs(self._offset()) > math.radians(self.tilt_min_deg)
        start = self._local(self._pos)
        held = _first_sustained(self._calm & away, n, start)
        back = _first_sustained(self._calm & ~away, n, start)
        if held is None and back is None:
            return self._wait()
        if back is not None and (held is None or back < held):
            return self._go(STILL, back)
        assert held is not None
        self._hold_angle = float(np.mean(self._x[held - n + 1 : held + 1]))
        self._emit(ReleaseKind.HELD, held, held, angle_rad=self._hold_angle)
        return self._go(HELD, held)

    def _step_held(self) -> bool:
        side = math.copysign(1.0, self._hold_angle - self.baseline_rad_)
        j = _first(side * self._smooth < -math.radians(self.leave_rate_deg_s), self._local(self._pos))
        if j is None:
            return self._wait()
        n = self._n(1.0)
        self._hold_angle = float(np.mean(self._x[max(0, j - n) : j + 1]))
        self._leave_index = j + self._first
        return self._go(LEAVING, j)

    def _step_leaving(self) -> bool:
        """Released (swung through rest), put back / re-held (calm again), or timed out."""
        offset = self._offset()
        side = math.copysign(1.0, self._hold_angle - self.baseline_rad_)
        start = self._local(self._pos)
        leave = self._local(self._leave_index)
        through_rad = max(
            math.radians(self.swing_through_deg), 0.05 * abs(self._hold_angle - self.baseline_rad_)
        )
        swung = _first(side * offset < -through_rad, start)
        calm = _first_sustained(self._calm, self._n(self.hold_min_s), max(start, leave))
        timeout = _first(self._t - self._t[leave] > self.confirm_timeout_s, start)
        found = [j for j in (swung, calm, timeout) if j is not None]
        if not found:
            return self._wait()
        j = min(found)
        if j == swung:
            self._swung_index = j + self._first
            return self._go(SWUNG, j)
        if abs(offset[j]) > math.radians(self.tilt_min_deg):
            return self._go(HELD if j == calm else TILTED, j)
        self._emit(ReleaseKind.PUT_BACK, j, j, angle_rad=self._hold_angle)
        return self._go(STILL, j)

    def _step_decaying(self) -> bool:
        assert self._release is not None
        n = self._n(self.settle_window_s)
        start = max(self._local(self._pos), self._local(self._release.index) + n - 1)
        quiet = _first_sustained(np.abs(self._offset()) < math.radians(self.settle_deg), n, start)
        timeout = _first(self._t - self._release.release_t > self.decay_timeout_s, self._local(self._pos))
        if quiet is None and timeout is None:
            return self._wait()
        if quiet is not None and (timeout is None or quiet <= timeout):
            settle, confirmed, ended = quiet - n + 1, quiet, DecayEnd.SETTLED
            self.baseline_rad_ = float(np.mean(self._x[settle : quiet + 1]))
        else:
            assert timeout is not None
            settle, confirmed, ended = timeout, timeout, DecayEnd.TIMEOUT
        self._emit(
            ReleaseKind.SETTLED,
            settle,
            confirmed,
            release_t=self._release.release_t,
            settle_s=float(self._t[settle] - self._release.release_t),
            ended=ended,
        )
        self._release = None
        return self._go(STILL, confirmed)

    # ---- locating the release ----------------------------------------

    def _step_swung(self) -> bool:
        """Wait for a few quarter cycles of free motion: the decay's own dynamics pin the release down."""
        leave, swung = self._local(self._leave_index), self._local(self._swung_index)
        end = leave + round(self.fit_quarters * (swung - leave))
        if end >= self._t.size:
            return self._wait()
        self._release = self._locate_release(leave, end)
        return self._go(DECAYING, end)

    def _locate_release(self, leave: int, end: int) -> ReleaseEvent:
        """Emit the release at the instant the held motion before and the decay equation after, fitted
        jointly over several quarter cycles, explain best (``release_instant``)."""
        lo = max(0, leave - self._n(self.fit_before_s))
        dt = 1.0 / float(self.rate_hz_ or 1.0)
        if leave - lo < 4:  # streamed in while already moving: no hold to fit, report the departure (the
            # instant's interval unknown: the hand may have let go any time before)
            return self._emit(ReleaseKind.RELEASED, leave, end, angle_rad=float(self._x[leave]),
                              rate_rad_s=float(self._r[leave]), release_t=float(self._t[leave]),
                              release_se_s=dt)  # fmt: skip
        window = slice(lo, end + 1)
        first = max(lo + 2, leave - self._n(self.scan_back_s))
        scan = range(first - lo, leave - lo + 1, self._n(0.01))  # every 10 ms before the departure
        found = find_release_instant(self._t[window], self._x[window], self._r[window], leave - lo,
                                     self.baseline_rad_, scan, dt)  # fmt: skip
        tau = found.t_s
        index = int(np.searchsorted(self._t, tau - 1e-9 * dt))
        tau = min(tau, float(self._t[index]))  # a rounding hair past the first free sample is that sample
        released = ReleaseKind.RELEASED
        return self._emit(released, index, end, angle_rad=found.angle_rad, rate_rad_s=found.rate_rad_s,
                          release_t=tau, release_se_s=found.se_s, release_u95_s=found.u95_s)  # fmt: skip


def detect_releases(samples: np.ndarray, axis: str = "auto", **settings: Any) -> list[ReleaseEvent]:
    """Offline: all events in a whole array of samples (``axis='auto'`` picks the tilted axis)."""
    chosen = pick_axis(samples) if axis == "auto" else axis
    return ReleaseDetector(axis=chosen, **settings).fit(samples).events_


def pick_axis(samples: np.ndarray) -> str:
    """The axis that was tilted: the one whose angle spans the widest range (robust percentiles)."""
    if samples.size == 0:
        raise InputError("no samples to pick an axis from")
    spans = {}
    for axis, (angle_field, _) in AXIS_FIELDS.items():
        values = samples[angle_field][np.isfinite(samples[angle_field])]
        spans[axis] = float(np.subtract(*np.percentile(values, [99.5, 0.5]))) if values.size else 0.0
    return max(spans, key=spans.__getitem__)
