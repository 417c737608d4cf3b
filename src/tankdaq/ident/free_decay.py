"""Where the free decay in a real record ends, and the cut there.

A towing-tank record goes on after the decay stops being free: the carriage
decelerates, someone pushes the model again, a wave comes back from the tank
end, or the roll sinks into the sensor noise. Fitting the whole record moves
the coefficients, so identify, campaign and diagnose cut each run where its
free part ends and say so in one line (time and reason).

The test works on the half-cycle peaks of the angle (sub-sample parabolas, so
noise matters little): a free decay loses energy every half-cycle, smoothly.
The free part ends at the last clean peak before

- a peak higher than the one a full cycle before (a second excitation),
- a half-cycle losing far more than the ones before, a jump of the midline
  between peaks, or a half-period out of step (a disturbance),
- a peak within the noise (the signal sinks into the noise),
- a change in a speed, sway or yaw channel when the record has one (the
  carriage stops: speed falls by a fifth),
- a stretch with no samples longer than a quarter of a half-period (its peaks
  are missing; a few dropped packets are no end).

Used by both readers (a CSV with several releases splits at each new
excitation) and ident; it imports only ``records`` and ``ident.signals``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from enum import StrEnum

import numpy as np

from ..errors import InputError
from ..records import DecayRun
from .signals import half_cycle_peaks, white_noise_level


class EndKind(StrEnum):
    """Why a free decay ends (``FreeDecayEnd.kind``, ``Cut.kind``; the cut's JSON says its value)."""

    EXCITATION = "excitation"
    DISTURBANCE = "disturbance"
    NOISE = "noise"
    CHANNEL = "channel"
    RECORD = "record"
    GIVEN = "given"


class ChannelKind(StrEnum):
    """What a recorded channel beside the angle measures, when its name says so (``channel_kind``)."""

    SPEED = "speed"
    SWAY = "sway"
    YAW = "yaw"


#: A peak within this many noise sigmas of the equilibrium is noise.
NOISE_PEAKS = 5.0
#: A half-cycle losing more than this many times the largest relative loss of the two before it is
#: not free (damping does not jump).
LOSS_JUMP = 2.5
#: The midline between peaks may wander by this fraction of the amplitude (nonlinear restoring).
MIDLINE_FRACTION = 0.15
#: A half-period may differ from the median of the three before by this fraction.
HALF_PERIOD_FRACTION = 0.25
#: The carriage stops when the one-period mean speed falls by this fraction (from at least MOVING_M_S).
SPEED_DROP = 0.2
MOVING_M_S = 0.05
#: A yaw or sway channel leaves its level by this many times its spread over the first two periods,
#: and by at least the floor (rad for yaw, m for sway).
CHANNEL_SPREADS = 8.0
CHANNEL_FLOORS = {ChannelKind.YAW: math.radians(1.0), ChannelKind.SWAY: 0.05}
#: A stretch without samples longer than this many half-periods (and time steps) ends the free part.
GAP_HALF_PERIODS, GAP_STEPS = 0.25, 5.0
#: Kinds of end after which a CSV record may hold another release (a carriage stop ends the record).
SPLIT_AFTER = (EndKind.EXCITATION, EndKind.NOISE)


@dataclass(frozen=True)
class FreeDecayEnd:
    """The end of the free part: ``index`` is the first sample left out (``t.size`` when none)."""

    index: int
    t_s: float
    kind: EndKind
    reason: str


@dataclass(frozen=True)
class Cut:
    """What was kept of one run and why, times in s from the run's first sample."""

    run: str
    start_s: float
    end_s: float
    kind: EndKind
    reason: str

    @property
    def line(self) -> str:
        """The one line identify, campaign and diagnose print."""
        return f"{self.run}: free decay {self.start_s:.2f}..{self.end_s:.2f} s after release ({self.reason})"

    def as_dict(self) -> dict[str, object]:
        return asdict(self) | {"kind": self.kind.value, "line": self.line}  # plain text in files


@dataclass(frozen=True)
class _Peaks:
    """Half-cycle peaks of a run: sample indices, times, signed values, and the noise level."""

    index: np.ndarray
    t: np.ndarray
    value: np.ndarray
    sigma: float


def _peaks(run: DecayRun) -> _Peaks | None:
    """Peaks about the median (a first-guess equilibrium: it only has to split the half-cycles)."""
    angle = run.angle
    sigma = max(white_noise_level(angle), 1e-3 * float(np.max(np.abs(angle - np.median(angle)))))
    guess = float(np.median(angle))
    index = half_cycle_peaks(angle - guess)
    if index.size < 3:
        return None
    width = max(2, round(0.1 * float(np.median(np.diff(index)))))  # a tenth of a half-period
    value = np.array([_parabola_peak(angle, i, width) for i in index])
    return _Peaks(index, run.t[index], value, sigma)


def _parabola_peak(y: np.ndarray, i: int, w: int) -> float:
    """The extremum of a parabola through ``y[i-w..i+w]``: a peak far less noisy than its sample."""
    lo, hi = max(i - w, 0), min(i + w + 1, y.size)
    if hi - lo < 3:
        return float(y[i])
    x = np.arange(lo, hi) - i
    c2, c1, c0 = np.polyfit(x, y[lo:hi], 2)
    vertex = -c1 / (2 * c2) if c2 != 0 else 0.0
    return float(c0 + c1 * vertex + c2 * vertex**2) if abs(vertex) <= w else float(y[i])


def find_free_end(run: DecayRun) -> FreeDecayEnd:
    """Where the free decay of ``run`` (starting at its release) ends; see the module docstring."""
    peaks = _peaks(run)
    found = _motion_end(run, peaks)
    if peaks is None:
        return found
    half_period = float(np.median(np.diff(peaks.t)))
    gap = _gap_end(run, half_period)
    # the swings just before a gap look out of step (its peaks are missing): the gap is the reason
    return gap if gap is not None and gap.t_s <= found.t_s + 2 * half_period else found


def _gap_end(run: DecayRun, half_period: float) -> FreeDecayEnd | None:
    """The first stretch with no samples longer than ``GAP_HALF_PERIODS`` of a half-period (and than
    ``GAP_STEPS`` time steps): peaks in it are missing, so the swings after it cannot be judged. A few
    dropped packets are far shorter and are no end (the fit runs over the times there are)."""
    steps = np.diff(run.t)
    if steps.size < 2:
        return None
    longest = max(GAP_STEPS * float(np.median(steps)), GAP_HALF_PERIODS * half_period)
    gaps = np.flatnonzero(steps > longest)
    if not gaps.size:
        return None
    i = int(gaps[0])
    return _end_at(
        run, i + 1, EndKind.RECORD,
        f"no samples for {steps[i]:.3g} s after {run.t[i] - run.t[0]:.2f} s: a gap in the record",
    )  # fmt: skip


def _motion_end(run: DecayRun, peaks: _Peaks | None) -> FreeDecayEnd:
    """Where the angle or a channel shows the decay is no longer free (the record's end if nowhere)."""
    angle_end, channel_end = _angle_end(run, peaks), _channel_end(run, peaks)
    if angle_end is None and channel_end is None:
        return FreeDecayEnd(
            run.t.size, float(run.t[-1] - run.t[0]), EndKind.RECORD, "no end found: whole record"
        )
    if angle_end is None or channel_end is None:
        return angle_end or channel_end  # type: ignore[return-value]
    if channel_end.index <= angle_end.index:
        return channel_end
    period_s = 2 * float(np.median(np.diff(peaks.t)))  # type: ignore[union-attr]
    if channel_end.t_s - angle_end.t_s < period_s:  # the roll felt the carriage stop first
        return FreeDecayEnd(
            angle_end.index, angle_end.t_s, EndKind.CHANNEL, f"{channel_end.reason}; the roll reacts first"
        )
    return angle_end


def _end_at(run: DecayRun, index: int, kind: EndKind, reason: str) -> FreeDecayEnd:
    index = int(min(max(index, 1), run.t.size))
    return FreeDecayEnd(index, float(run.t[index - 1] - run.t[0]), kind, reason)


def _angle_end(run: DecayRun, peaks: _Peaks | None) -> FreeDecayEnd | None:
    """The first half-cycle that a free decay cannot make, judged on swings (peak to peak).

    Swings need no equilibrium: ``swing[k]`` runs from peak k to peak k+1 and always shrinks in a
    free decay. The midline between three peaks is biased by the decrement, by about
    ``swing (1 - ratio)^2 / 8``; the test allows for it.
    """
    if peaks is None:
        return None
    swing = np.abs(np.diff(peaks.value))
    for k in range(1, swing.size):  # swing k ends at peak k+1; the last clean peak is k
        found = _swing_end(peaks, swing, k)
        if found is not None:
            return _end_at(run, *found)
    return _tail_end(run, peaks, swing)


def _swing_end(peaks: _Peaks, swing: np.ndarray, k: int) -> tuple[int, EndKind, str] | None:
    """Whether swing k is one a free decay cannot make: (the index where it ends, kind, reason)."""
    v, sigma = peaks.value, peaks.sigma
    before = int(peaks.index[k]) + 1
    if swing[k] / 2 < NOISE_PEAKS * sigma:
        return (
            int(peaks.index[k + 1]),
            EndKind.NOISE,
            f"the signal sinks into the noise: swing {math.degrees(swing[k]):.3g} deg, "
            f"noise {math.degrees(sigma):.2g} deg",
        )
    if swing[k] > swing[k - 1] + 4 * math.sqrt(2) * sigma:
        return (
            before,
            EndKind.EXCITATION,
            f"a second excitation: the swing grows from {math.degrees(swing[k - 1]):.3g} "
            f"to {math.degrees(swing[k]):.3g} deg",
        )
    ratio = swing[1:] / swing[:-1]
    loss = 1.0 - ratio[k - 1]
    usual_loss = max(1.0 - ratio[k - 3 : k - 1]) if k >= 3 else math.inf
    if loss > LOSS_JUMP * usual_loss + 4 * math.sqrt(2) * sigma / swing[k - 1]:
        return (
            before,
            EndKind.DISTURBANCE,
            f"a disturbance: a half-cycle loses {100 * loss:.0f} % of its swing, "
            f"{100 * usual_loss:.0f} % before",
        )
    if k >= 2:
        midline = (v[k - 1] + 2 * v[k] + v[k + 1]) / 4
        previous = (v[k - 2] + 2 * v[k - 1] + v[k]) / 4
        bias = swing[k - 2] * (1.0 - min(ratio[k - 2], 1.0)) ** 2 / 4
        if abs(midline - previous) > MIDLINE_FRACTION * swing[k] / 2 + bias + 5 * sigma:
            jump_deg = math.degrees(midline - previous)
            return before, EndKind.DISTURBANCE, f"a disturbance: the equilibrium jumps by {jump_deg:+.3g} deg"
    if k >= 3:
        half_periods = np.diff(peaks.t)
        usual = float(np.median(half_periods[k - 3 : k]))
        jitter = 8 * sigma / (math.pi * swing[k])  # zero-crossing time noise, relative
        if abs(half_periods[k] - usual) > (HALF_PERIOD_FRACTION + jitter) * usual:
            return (
                before,
                EndKind.DISTURBANCE,
                f"a disturbance: a half-period of {half_periods[k]:.3g} s, {usual:.3g} s before",
            )
    return None


def _tail_end(run: DecayRun, peaks: _Peaks, swing: np.ndarray) -> FreeDecayEnd | None:
    """After the last half-cycle: a long tail without one has settled, or was pushed aside."""
    v, sigma = peaks.value, peaks.sigma
    last = int(peaks.index[-1])
    rest = run.angle[last:]
    period_samples = 2 * int(np.median(np.diff(peaks.index)))
    if rest.size <= 2 * period_samples:
        return None
    shift = float(np.median(rest[period_samples:])) - (v[-2] + v[-1]) / 2
    if abs(shift) > MIDLINE_FRACTION * swing[-1] + 5 * sigma:
        return _end_at(
            run,
            last + period_samples // 2,
            EndKind.DISTURBANCE,
            f"a disturbance: the angle leaves its equilibrium by {math.degrees(shift):+.3g} deg",
        )
    return _end_at(
        run,
        last + period_samples // 2,
        EndKind.NOISE,
        f"the signal sinks into the noise after a last swing of {math.degrees(swing[-1]):.3g} deg",
    )


def channel_kind(name: str) -> ChannelKind | None:
    """speed, sway or yaw for a channel whose name says so (``carriage_speed_m_s``, ``psi``...), else None."""
    lowered = name.lower()
    for kind, words, exact in (
        (ChannelKind.SPEED, ("speed",), ("u", "u_m_s")),
        (ChannelKind.SWAY, ("sway",), ("v", "v_m_s")),
        (ChannelKind.YAW, ("yaw",), ("psi",)),
    ):
        if any(w in lowered for w in words) or lowered in exact:
            return kind
    return None


def _channel_end(run: DecayRun, peaks: _Peaks | None) -> FreeDecayEnd | None:
    """The first change in a speed, sway or yaw channel, from its one-period moving mean."""
    if peaks is None or not run.channels:
        return None
    period = 2 * int(np.median(np.diff(peaks.index)))
    if run.t.size < 3 * period:
        return None
    ends = []
    for name, values in run.channels.items():
        kind = channel_kind(name)
        if kind is None or not np.all(np.isfinite(values)):
            continue
        level = np.convolve(values, np.ones(period) / period, mode="valid")  # level[i]: mean of i..i+period
        reference = float(level[0])
        if kind == ChannelKind.SPEED:
            if abs(reference) < MOVING_M_S:
                continue
            changed = np.abs(level - reference) > SPEED_DROP * abs(reference)
            what = "the carriage speed changes"
        else:
            spread = float(np.ptp(level[:period]))
            changed = np.abs(level - reference) > max(CHANNEL_SPREADS * spread, CHANNEL_FLOORS[kind])
            what = f"the {kind} channel changes"
        hits = np.flatnonzero(changed)
        if hits.size:
            i = int(hits[0]) + period // 2  # the window's middle: where the change is under way
            unit = "m/s" if kind == ChannelKind.SPEED else ("deg" if kind == ChannelKind.YAW else "m")
            scale = math.degrees(1.0) if kind == ChannelKind.YAW else 1.0
            ends.append(
                _end_at(
                    run,
                    i,
                    EndKind.CHANNEL,
                    f"{what}: {name} {reference * scale:.3g} -> {level[hits[0]] * scale:.3g} {unit}",
                )
            )
    return min(ends, key=lambda e: e.index) if ends else None


def cut_free_decay(run: DecayRun, start_s: float | None = None, end_s: float | None = None) -> DecayRun:
    """The free part of ``run``: automatic end unless ``end_s`` is given; ``meta['cut']`` says what and why.

    ``start_s``/``end_s`` are seconds from the run's first sample (the release).
    """
    elapsed = run.t - run.t[0]
    first = 0 if start_s is None else int(np.searchsorted(elapsed, start_s, side="left"))
    if end_s is not None:
        stop = int(np.searchsorted(elapsed, end_s, side="right"))
        kind, reason = EndKind.GIVEN, f"--end {end_s:g} s"
    else:
        found = find_free_end(run)
        stop, kind, reason = found.index, found.kind, found.reason
        if found.kind == EndKind.RECORD and "split" in run.meta:  # the reader ended it at the next release
            kind, reason = EndKind(run.meta["split"][0]), run.meta["split"][1]
    if start_s is not None:
        reason += f"; --start {start_s:g} s"
    if stop - first < 20:
        raise InputError(
            f"{run.name}: fewer than 20 samples between {elapsed[min(first, elapsed.size - 1)]:.2f} s and "
            f"{elapsed[max(stop - 1, 0)]:.2f} s after the release ({reason}); widen --start/--end"
        )
    cut = run.window(first, stop)
    record = Cut(run.name, float(elapsed[first]), float(elapsed[stop - 1]), kind, reason)
    cut.meta["cut"] = record.as_dict()
    return cut


def cut_free_decays(
    runs: Sequence[DecayRun], start_s: float | None = None, end_s: float | None = None
) -> list[DecayRun]:
    """``cut_free_decay`` of every run (``--start``/``--end`` apply to each)."""
    if start_s is not None and end_s is not None and end_s <= start_s:
        raise InputError(f"--end {end_s:g} s must come after --start {start_s:g} s")
    return [cut_free_decay(run, start_s, end_s) for run in runs]


def cut_lines(runs: Sequence[DecayRun]) -> list[str]:
    """The one-line cut of every run that was cut."""
    return [str(cut["line"]) for run in runs if isinstance(cut := run.meta.get("cut"), dict)]
