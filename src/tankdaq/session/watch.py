"""The model watched between decays, on the session's one stream: drift, a bump, level.

Labs wait for still water and level the model before each run (ITTC 7.5-02-07-04.5 §3.1.6: record from
rest, no disturbance; docs/session.md). ``ModelWatch`` is a sink of the session's pipeline: from the
level check that sets a draft (its mean is the reference) and after each decay once the model is at rest
again, until the next release, it judges the decay axis over windows of ``WINDOW_S`` of device time:

- a window is quiet (the model at rest) when the angle's spread is at most ``STILL_SD_DEG`` (the level
  check's "at rest") and the rate of turn's rms about its mean at most ``STILL_RATE_DEG_S``; it is shaken
  when either is well above still water (``BUMP_SD_DEG``, ``BUMP_RATE_DEG_S``: more than a decay's
  swing once it has settled, under 0.5 deg); in between the model moves a little (not at rest, no bump);
- a shaken window that stays within ``TILT_MIN_DEG`` of the rest angle, followed by one that is not a
  tilt, is a **bump** (a window that goes further is the hand's tilt, the release detector's business);
- a quiet window whose mean is further than the plan's level tolerance from the reference is **drift**,
  one further than that from zero (and not drifted) is off **level**;
- a still water whose level creeps, the least-squares slope of its quiet windows' means over the last
  ``TREND_S`` (after the latest step in them, ``after_last_step``) at least ``TREND_T`` standard errors
  (``creep_deg_min``) and ``TREND_DEG_MIN``, is a **trend**: a drift on its way, said before it crosses
  the tolerance (over below half that rate).

Each is said once as a ``ModelMoved`` event while it stands: ``on_block`` returns it and the pipeline
tells every listener. At the next release ``at_release`` keeps what stood then: a bump the model had not
been quiet ``SETTLED_S`` after before the tilt began, a trend, a drift or level standing; the session's checks
flag that decay (``checks.watch_reasons``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..acquire.decay import LiveDecay
from ..acquire.events import Event, ModelMoved, MovedKind, PutBack, Released
from ..acquire.release import TILT_MIN_DEG
from ..acquire.sinks import Sink
from ..device.driver import StreamBlock
from ..samples import AXIS_FIELDS
from .checks import STILL_SD_DEG

#: Device seconds of each window the watch judges (a bump shorter than two of them may pass unseen).
WINDOW_S = 1.0
#: Rate of turn (rms about its mean, deg/s) at most which the model is at rest: well above a still-water
#: gyro's noise (MTi-G at 400 Hz: 0.4 deg/s rms).
STILL_RATE_DEG_S = 1.0
#: A window is shaken (a bump, unless a tilt follows) above this angle spread (deg) or rate rms (deg/s): a
#: decay's swing once settled (under 0.5 deg, ITTC) stays below both at periods over 1.5 s.
BUMP_SD_DEG = 0.5
BUMP_RATE_DEG_S = 2.0
#: Quiet device seconds after a bump before the model counts as settled (the release detector's settle
#: window: a decay ends after this long below its threshold).
SETTLED_S = 3.0
#: A still water creeping faster than this (deg/min) is a **trend**: at a 1 deg level tolerance a drift
#: within a minute; a model taking on water heels some deg/min (``physics.scenario.DRIFT_DEG_MIN``).
TREND_DEG_MIN = 1.0
#: The trend is the least-squares slope of the quiet windows' means over the last ``TREND_S`` device
#: seconds of still water, judged once there are ``TREND_MIN_S`` of them: a 1 s mean of MTi-G angle
#: noise (0.02 deg rms at 100 Hz) scatters by 0.002 deg, so the slope's own scatter over 10 s is about
#: 0.013 deg/min.
TREND_S = 20.0
TREND_MIN_S = 10.0
#: ... and only when the slope is this many of its standard errors: a settled decay's last swing
#: scatters the means about any line, and is not a creep. A step in the still water (a sensor's bias
#: settling, the model nudged to a new rest) is a new level, not a creep: the fit starts after it.
TREND_T = 6.0
#: Two levels are a step when they fit the means this many times better (residual sum of squares) than
#: a line bent once. A step that could pass for a creep of 1 deg/min over a short stretch is some 0.1 deg,
#: 45 noise widths of a 1 s mean: it fits 35 times better or more (135 in the median); 10 widths, 7.
STEP_BETTER = 4.0


@dataclass(frozen=True)
class _Window:
    """One judged window (degrees): where it starts and ends, mean and spread, the rate's rms, how far
    from rest it went."""

    t_s: float
    end_s: float
    mean_deg: float
    spread_deg: float
    rate_deg_s: float
    excursion_deg: float

    @property
    def quiet(self) -> bool:
        return self.spread_deg <= STILL_SD_DEG and self.rate_deg_s <= STILL_RATE_DEG_S

    @property
    def shaken(self) -> bool:
        return self.spread_deg > BUMP_SD_DEG or self.rate_deg_s > BUMP_RATE_DEG_S


class ModelWatch(Sink):
    """Drift, bumps and level between decays; ``arm(reference_deg)`` once a draft's level is measured."""

    def __init__(self, axis: str, level_tolerance_deg: float) -> None:
        self.angle_field, self.rate_field = AXIS_FIELDS[axis]
        self.level_tolerance_deg = level_tolerance_deg
        self._said: list[ModelMoved] = []  # what this block's windows found, returned by ``on_block``
        self.reference_deg: float | None = None  # None: disarmed (a draft being set)
        self.at_release: tuple[int, list[ModelMoved]] | None = None  # (decay, what stood at its release)
        self.disarm()

    def arm(self, reference_deg: float) -> None:
        """Watch from now on against ``reference_deg``, the still water measured when the draft was set."""
        self.disarm()
        self.reference_deg = reference_deg

    def disarm(self) -> None:
        """Stop watching (the operator changes the draft: the model is handled on purpose)."""
        self.reference_deg = None
        self._blocks: list[np.ndarray] = []
        self._rest_deg: float | None = None  # the mean of the last quiet window
        self._quiet_since = math.nan  # device time the model has been quiet since (nan: it is not)
        self._quiet_s = 0.0  # how long the latest quiet stretch lasted (up to its last quiet window)
        self._settling = False  # a decay's tail: no bump until the first quiet window
        self._pending: _Window | None = None  # a shaken window near rest: a bump unless a tilt follows
        self._bump: ModelMoved | None = None  # the last bump since the last decay
        self._bump_open = False  # said for the disturbance under way
        self._tilted = False  # the hand's tilt seen: windows wait for the release or the put-back
        self._standing: dict[MovedKind, ModelMoved] = {}  # drift or level, said and not yet over
        self._means: list[tuple[float, float]] = []  # (middle, mean) of the quiet windows of this still water
        self._trend: ModelMoved | None = None  # a creeping still water, said and not yet over

    # ---- the sink ----------------------------------------

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> list[ModelMoved]:
        """What the block's windows found (each ``ModelMoved`` once while it stands)."""
        if decay is not None:  # a decay under way: its motion is the recording's
            self._blocks, self._settling, self._pending = [], True, None
            return []
        if self.reference_deg is None or not block.samples.size:
            return []
        self._blocks.append(block.samples)
        if float(self._blocks[-1]["t"][-1] - self._blocks[0]["t"][0]) < WINDOW_S:
            return []
        samples = np.concatenate(self._blocks)
        t, start = samples["t"], 0
        while t[-1] - t[start] >= WINDOW_S:  # windows of device time, however the reads cut the stream
            stop = int(np.searchsorted(t, t[start] + WINDOW_S))
            window = self._window(samples[start:stop])
            if window is not None:
                self._judge(window)
            start = stop
        self._blocks = [samples[start:]]
        said, self._said = self._said, []
        return said

    def on_event(self, event: Event) -> None:
        if isinstance(event, Released) and self.reference_deg is not None:
            self.at_release = (event.run, self._stood())
            self._bump, self._bump_open, self._tilted, self._quiet_since = None, False, False, math.nan
            self._quiet_s, self._means, self._trend = 0.0, [], None
        elif isinstance(event, PutBack):
            self._tilted = False

    def standing_at(self, decay: int) -> list[ModelMoved]:
        """What stood when ``decay`` was released (empty: nothing, or the watch was not armed then)."""
        if self.at_release is None or self.at_release[0] != decay:
            return []
        return self.at_release[1]

    # ---- judging ----------------------------------------

    def _window(self, samples: np.ndarray) -> _Window | None:
        angle = np.degrees(samples[self.angle_field])
        rate = np.degrees(samples[self.rate_field])
        angle, rate = angle[np.isfinite(angle)], rate[np.isfinite(rate)]
        if not angle.size:
            return None
        rest = self._rest_deg if self._rest_deg is not None else self.reference_deg
        assert rest is not None
        return _Window(
            float(samples["t"][0]),
            float(samples["t"][-1]),
            float(angle.mean()),
            float(angle.std()),
            float(rate.std()) if rate.size else 0.0,
            float(np.max(np.abs(angle - rest))),
        )

    def _judge(self, window: _Window) -> None:
        if not window.quiet:
            self._means = []  # the still water's stretch is over: a trend is fitted over one stretch
        if self._tilted and (not window.quiet or window.excursion_deg >= TILT_MIN_DEG):
            return  # held or swinging for the release: the detector's
        if window.quiet:
            self._quiet(window)
            return
        if window.excursion_deg >= TILT_MIN_DEG:  # the hand's tilt (or a shove as big: a decay if released)
            self._tilted, self._pending = True, None
            return
        if self._pending is not None:  # a window near rest after the shaken one: not a tilt, a bump
            self._said_bump(self._pending)
            return
        self._quiet_since = math.nan  # not at rest
        if not (self._settling or self._bump_open) and window.shaken:
            self._pending = window  # a bump, or the first moments of a tilt: the next window says

    def _quiet(self, window: _Window) -> None:
        if self._pending is not None:  # shaken, then at rest: a knock, not a tilt
            self._said_bump(self._pending)
        self._pending, self._bump_open, self._settling = None, False, False
        self._tilted = False  # back near rest without a release (put back)
        if math.isnan(self._quiet_since):
            self._quiet_since = window.t_s
        self._quiet_s = window.end_s - self._quiet_since
        self._rest_deg = window.mean_deg
        self._check_level(window)
        self._check_trend(window)

    def _said_bump(self, window: _Window) -> None:
        self._pending, self._quiet_since, self._quiet_s = None, math.nan, 0.0
        if self._bump_open:
            return
        self._bump_open = True
        self._bump = self._moved(MovedKind.BUMP, window, STILL_SD_DEG)
        self._said.append(self._bump)

    def _check_level(self, window: _Window) -> None:
        reference, tolerance = self.reference_deg, self.level_tolerance_deg
        assert reference is not None
        kind = (
            MovedKind.DRIFT
            if abs(window.mean_deg - reference) > tolerance
            else MovedKind.LEVEL
            if abs(window.mean_deg) > tolerance
            else None
        )
        if kind is None:
            self._standing = {}
        elif kind not in self._standing:
            self._standing = {kind: self._moved(kind, window, tolerance)}
            self._said.append(self._standing[kind])

    def _check_trend(self, window: _Window) -> None:
        """Fit the still water's creep over its last ``TREND_S``; say a trend once while it lasts."""
        self._means.append((0.5 * (window.t_s + window.end_s), window.mean_deg))
        newest_s = self._means[-1][0]
        self._means = [(t, mean) for t, mean in self._means if newest_s - t <= TREND_S]
        times_s, means_deg = (np.array(column) for column in zip(*self._means, strict=True))
        first = after_last_step(times_s, means_deg)
        self._means, times_s, means_deg = self._means[first:], times_s[first:], means_deg[first:]
        if newest_s - times_s[0] < TREND_MIN_S:
            return
        slope_deg_min = creep_deg_min(times_s, means_deg)
        if self._trend is None and abs(slope_deg_min) >= TREND_DEG_MIN:
            self._trend = self._moved(MovedKind.TREND, window, self.level_tolerance_deg, slope_deg_min)
            self._said.append(self._trend)
        elif not abs(slope_deg_min) >= TREND_DEG_MIN / 2:  # over (nan: no clear creep): half, not to flicker
            self._trend = None

    def _moved(
        self, kind: MovedKind, window: _Window, limit_deg: float, slope_deg_min: float = math.nan
    ) -> ModelMoved:
        assert self.reference_deg is not None
        return ModelMoved(
            kind,
            window.mean_deg,
            window.spread_deg,
            window.rate_deg_s,
            self.reference_deg,
            limit_deg,
            window.t_s,
            slope_deg_min,
        )

    def _stood(self) -> list[ModelMoved]:
        """What stood at a release: a bump not followed by ``SETTLED_S`` of quiet before the tilt began,
        a trend, and a drift or off level."""
        unsettled = self._bump is not None and (self._bump_open or self._quiet_s < SETTLED_S)
        trend = [self._trend] if self._trend is not None else []
        return ([self._bump] if unsettled and self._bump else []) + trend + list(self._standing.values())


def after_last_step(times_s: np.ndarray, means_deg: np.ndarray) -> int:
    """Index of the first mean after a step in the still water (0: none). A step is two levels, with at
    most one mean between them (the window the step fell in), the new one held for two means at least;
    it is taken when it fits the means ``STEP_BETTER`` times better than any line that bends once (a
    creep setting in, slowing or stopping bends; it does not jump)."""
    if means_deg.size < 4:
        return 0
    bent_deg2 = min(_bent_line_rss(times_s, means_deg, knot_s) for knot_s in times_s[1:-1])
    best_deg2, first_after = bent_deg2 / STEP_BETTER, 0
    for after in range(2, means_deg.size - 1):  # the new level holds for two means at least
        for before in (after, after - 1):  # the window the step fell in belongs to neither level
            levels_deg2 = float(
                np.var(means_deg[:before]) * before + np.var(means_deg[after:]) * (means_deg.size - after)
            )
            if levels_deg2 < best_deg2:
                best_deg2, first_after = levels_deg2, after
    return first_after


def _bent_line_rss(times_s: np.ndarray, means_deg: np.ndarray, knot_s: float) -> float:
    """The residual sum of squares of the best continuous line through ``means_deg`` that bends at
    ``knot_s``."""
    basis = np.column_stack([np.ones_like(times_s), times_s - knot_s, np.maximum(times_s - knot_s, 0.0)])
    coefficients = np.linalg.lstsq(basis, means_deg, rcond=None)[0]
    return float(np.sum((means_deg - basis @ coefficients) ** 2))


def creep_deg_min(times_s: np.ndarray, means_deg: np.ndarray) -> float:
    """The still water's creep (deg/min): the least-squares slope of window means at ``times_s`` when it
    is ``TREND_T`` of its standard errors or more; nan when the means show no clear line."""
    centred_s = times_s - times_s.mean()
    spread_s2 = float(np.sum(centred_s**2))
    if times_s.size < 3 or spread_s2 <= 0:
        return math.nan
    slope_deg_s = float(np.sum(centred_s * (means_deg - means_deg.mean())) / spread_s2)
    residual_deg = means_deg - means_deg.mean() - slope_deg_s * centred_s
    standard_error_deg_s = math.sqrt(float(np.sum(residual_deg**2)) / (times_s.size - 2) / spread_s2)
    return slope_deg_s * 60 if abs(slope_deg_s) >= TREND_T * standard_error_deg_s else math.nan
