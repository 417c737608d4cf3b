"""A decay run as the identification sees it: time, angle, rate, extra channels.

Recordings (MCAP), CSV files and the simulator all become ``DecayRun`` objects,
so estimators and the discrepancy workflow never care where data came from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from .errors import BadIdentificationInput


@dataclass
class DecayRun:
    """One free decay of one axis, from the release onwards.

    ``t`` in s (starting anywhere), ``angle`` in rad, ``rate`` in rad/s or None
    when only the angle was measured. ``channels`` holds other measured signals
    on the same time base (e.g. ``heave_m``, ``acc_z_m_s2``, ``other_angle``),
    ``meta`` whatever is known about the run (hull, draft, nominal angle, file).
    """

    t: np.ndarray
    angle: np.ndarray
    rate: np.ndarray | None = None
    axis: str = "roll"
    name: str = "run"
    channels: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)  # free-form: JSON values from files and settings
    excluded: np.ndarray | None = None  # samples fits leave out (a sensor clipped: samples.StatusTally)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=float)
        self.angle = np.asarray(self.angle, dtype=float)
        if self.rate is not None:
            self.rate = np.asarray(self.rate, dtype=float)
        if self.excluded is not None:
            self.excluded = np.asarray(self.excluded, dtype=bool)
        self.validate()

    def validate(self) -> None:
        """Refuse data no estimator can use, with a message that says what is wrong."""
        n = self.t.size
        if n == 0:
            raise BadIdentificationInput(f"{self.name}: the record is empty")
        if self.angle.shape != self.t.shape:
            raise BadIdentificationInput(f"{self.name}: time and angle have different lengths")
        if self.rate is not None and self.rate.shape != self.t.shape:
            raise BadIdentificationInput(f"{self.name}: time and rate have different lengths")
        if self.excluded is not None and self.excluded.shape != self.t.shape:
            raise BadIdentificationInput(f"{self.name}: time and the excluded samples have different lengths")
        for label, arr in (("time", self.t), ("angle", self.angle), ("rate", self.rate)):
            if arr is not None and not np.all(np.isfinite(arr)):
                raise BadIdentificationInput(
                    f"{self.name}: the {label} column holds NaN or infinite values; clean or cut the record"
                )
        if n > 1 and np.any(np.diff(self.t) <= 0):
            raise BadIdentificationInput(f"{self.name}: time is not strictly increasing")

    @property
    def kept(self) -> np.ndarray:
        """The samples a fit uses (all but ``excluded``)."""
        return np.ones(self.t.shape, dtype=bool) if self.excluded is None else ~self.excluded

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0

    @property
    def sample_rate(self) -> float:
        """Median sample rate in Hz."""
        return float(1.0 / np.median(np.diff(self.t))) if self.t.size > 1 else float("nan")

    def window(self, start: int, stop: int | None = None) -> DecayRun:
        """A copy restricted to samples ``start:stop`` (channels cut alike)."""
        sl = slice(start, stop)
        return DecayRun(
            t=self.t[sl],
            angle=self.angle[sl],
            rate=None if self.rate is None else self.rate[sl],
            axis=self.axis,
            name=self.name,
            channels={k: v[sl] for k, v in self.channels.items()},
            meta=dict(self.meta),
            excluded=None if self.excluded is None else self.excluded[sl],
        )


class Verdict(StrEnum):
    """What a guided session's operator said of a decay (its log, its catalogue row, the report's list)."""

    ACCEPTED = "accepted"
    REJECTED = "rejected"


class DecayEnd(StrEnum):
    """How a recorded decay ended: part of the record, in its file and its catalogue row.

    Only ``SETTLED`` and ``TIMEOUT`` decays are whole; the others hold what arrived and are left out of
    ``--runs`` campaigns and reference fits unless asked for (``DecayEnd.whole``).
    """

    SETTLED = "settled"  #: the swing fell below the settle threshold
    TIMEOUT = "timeout"  #: the decay went on to the longest a decay may last
    STOPPED = "stopped"  #: stopped by the operator (Ctrl-C, SIGTERM, a closed terminal) mid-decay
    STREAM_ENDED = "stream_ended"  #: the stream or replayed file ended mid-decay
    DEVICE_LOST = "device_lost"  #: the device went away mid-decay
    ERROR = "error"  #: closed after an exception in the pipeline
    CUT = "cut"  #: the writer never closed the file (a crash, kill -9, power cut): no footer
    RECOVERED = "recovered"  #: a cut file rebuilt by ``tankdaq recover``

    @property
    def whole(self) -> bool:
        """True when the file holds the whole decay, so its fit may stand for it."""
        return self in (DecayEnd.SETTLED, DecayEnd.TIMEOUT)

    @property
    def words(self) -> str:
        """How it ended in plain words ("stopped by the operator")."""
        return _END_WORDS[self]

    def said(self, after_s: float | None = None) -> str:
        """How it ended, for a line a person reads: a decay that is not whole says so (``after_s``: the
        seconds recorded after its release, when known)."""
        if self.whole:
            return self.words
        when = f" {after_s:.1f} s after the release" if after_s is not None and math.isfinite(after_s) else ""
        return f"{self.words}{when}: partial, left out of campaigns"

    @classmethod
    def of_settle_reason(cls, reason: object) -> DecayEnd | None:
        """The end a recording's ``settle_reason`` metadata names; older files' reasons included."""
        text = str(reason or "")
        try:
            return cls(text)
        except ValueError:
            return _LEGACY_SETTLE_REASONS.get(text)


#: The ``settle_reason`` words files written before ``DecayEnd`` carry. ``note`` meant stopped or the stream's
#: end; it cannot be told which, so it counts as stopped (not whole).
_LEGACY_SETTLE_REASONS = {
    "amplitude": DecayEnd.SETTLED,
    "note": DecayEnd.STOPPED,
    "unplug": DecayEnd.DEVICE_LOST,
}

#: Each end in the words of a line a person reads (``DecayEnd.said``).
_END_WORDS = {
    DecayEnd.SETTLED: "settled",
    DecayEnd.TIMEOUT: "timed out at the longest a decay may last",
    DecayEnd.STOPPED: "stopped by the operator",
    DecayEnd.STREAM_ENDED: "the stream ended",
    DecayEnd.DEVICE_LOST: "the device went away",
    DecayEnd.ERROR: "closed after an error",
    DecayEnd.CUT: "cut: its writer never closed the file",
    DecayEnd.RECOVERED: "rebuilt by tankdaq recover from a cut file",
}


def partial_end(run: DecayRun) -> str | None:
    """How ``run``'s decay ended, in words, when its recording holds only part of it (``meta["ended"]``
    not whole); None for a whole decay or a file that does not say."""
    ended = DecayEnd.of_settle_reason(run.meta.get("ended"))
    if ended is None or ended.whole:
        return None
    return ended.said(run.meta.get("ended_after_s"))
