"""One decay read twice from two files: the same samples, whatever the files' bytes or where each was cut.

A lab's folder holds a run's CSV and the same run re-saved by a spreadsheet (other decimals, another
separator, degrees where the first had radians), a copy in a colleague's "selected" folder, or that
copy trimmed to the cycles someone liked. The files differ, so neither their hashes nor an export's
metadata tell (``store.inputs.read_twice``); their decays, read, share samples. Fitted together such a
decay counts twice: every interval narrows for nothing. Two decays share a stretch when, at one
alignment, their sampling instants agree (to ``TIME_TO`` of a step) and their angles agree to
``SAME_TO`` of the amplitude sample by sample: two real decays never do, their noise alone differs by
more (a sensor's 0.01 deg is 1e-3 of a 10 deg decay). A stretch that is at least half of the shorter
decay (and ``MIN_SHARED`` samples) makes the two one decay.

Such a stretch is the shorter decay's first or last half at least (a stretch inside it would make the
other one the shorter), so it holds the largest angle of one of the shorter decay's halves: those two
samples are looked up among every decay's samples at once (one sorted index), and only where one is
found, with its neighbours, is the whole stretch compared.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..records import DecayRun

#: Two decays whose angles agree to this fraction of their amplitude, sample by sample, are one (a CSV
#: re-saved with four significant digits still agrees to 1e-4).
SAME_TO = 2e-4
#: ...and whose sampling instants, from the stretch's start, agree to this fraction of a time step.
TIME_TO = 0.1
#: Fewer shared samples than this never make two decays one (a few samples can agree by rounding).
MIN_SHARED = 20
#: No sample.
NONE = np.zeros(0, dtype=np.int64)


def shared_samples(first: DecayRun, second: DecayRun) -> int:
    """How many consecutive samples the two decays hold in common (0: none) where that stretch is at
    least half of the shorter one."""
    short, long_ = (first, second) if first.t.size <= second.t.size else (second, first)
    index = _SampleIndex([short, long_])
    among = np.array([False, True])
    return max(
        (_found(short, long_, anchor, index, (0, 1), index.holding(short, anchor, among).get(1, NONE))
         for anchor in _anchors(short)),
        default=0,
    )  # fmt: skip


def repeated_decays(runs: Sequence[DecayRun]) -> dict[int, int]:
    """Index of each decay that repeats another -> the index of the one kept: of two, the longer stays
    (the earlier where they are as long)."""
    index = _SampleIndex(runs)
    kept = np.zeros(len(runs), dtype=bool)
    repeats: dict[int, int] = {}
    for i in sorted(range(len(runs)), key=lambda i: (-runs[i].t.size, i)):
        first = _kept_holder(runs, i, index, kept)
        if first is None:
            kept[i] = True
        else:
            repeats[i] = first
    return dict(sorted(repeats.items()))


def _kept_holder(runs: Sequence[DecayRun], i: int, index: _SampleIndex, kept: np.ndarray) -> int | None:
    """The first kept decay that shares at least half of decay ``i`` with it (None: none does)."""
    for anchor in _anchors(runs[i]):
        for j, matches in index.holding(runs[i], anchor, kept).items():
            if 2 * _found(runs[i], runs[j], anchor, index, (i, j), matches) >= runs[i].t.size:
                return j
    return None


def _anchors(run: DecayRun) -> list[int]:
    """The sample of the largest angle in each half of ``run`` (none for a run too short to judge)."""
    if run.t.size < MIN_SHARED:
        return []
    half = run.t.size // 2
    return [int(np.argmax(np.abs(run.angle[:half]))), half + int(np.argmax(np.abs(run.angle[half:])))]


class _SampleIndex:
    """Every sample of every decay, sorted by angle: which decays hold a value (and its next sample) in
    O(log n), for all of them at once."""

    def __init__(self, runs: Sequence[DecayRun]) -> None:
        angles = [np.asarray(run.angle, dtype=float) for run in runs]
        sizes = np.array([a.size for a in angles], dtype=np.int64)
        values = np.concatenate(angles) if angles else np.zeros(0)
        following = np.concatenate([np.append(a[1:], np.nan) for a in angles]) if angles else np.zeros(0)
        order = np.argsort(values, kind="stable")
        self.values, self.following = values[order], following[order]
        self.owner = np.repeat(np.arange(len(angles)), sizes)[order]
        self.sample = (np.arange(values.size) - np.repeat(np.cumsum(sizes) - sizes, sizes))[order]
        self.amplitude = np.array([np.max(np.abs(a)) if a.size else 0.0 for a in angles])
        self.step = np.array([np.median(np.diff(run.t)) if run.t.size > 1 else 0.0 for run in runs])
        self.reach = SAME_TO * float(np.max(self.amplitude, initial=0.0))  # every pair's tolerance, at most

    def holding(self, run: DecayRun, anchor: int, among: np.ndarray) -> dict[int, np.ndarray]:
        """The decays in ``among`` (a mask) that may hold ``run``'s sample ``anchor`` and the one after
        it (to the largest pair's tolerance), in order, each with the samples that may be it."""
        reach = self.reach
        value = float(run.angle[anchor])
        lo, hi = np.searchsorted(self.values, [value - reach, value + reach])
        owners, samples = self.owner[lo:hi], self.sample[lo:hi]
        if anchor + 1 < run.t.size:  # a chance match of one value rarely has the next one too
            after = np.abs(self.following[lo:hi] - float(run.angle[anchor + 1])) <= reach
            owners, samples = owners[after], samples[after]
        return {int(j): samples[owners == j] for j in np.unique(owners) if among[j]}


def _found(
    short: DecayRun,
    long_: DecayRun,
    anchor: int,
    index: _SampleIndex,
    pair: tuple[int, int],
    matches: np.ndarray,
) -> int:
    """The samples ``short`` shares with ``long_`` (decays ``pair`` of ``index``) at an alignment that
    puts short's sample ``anchor`` on one of long's ``matches`` (0: none)."""
    step = float(index.step[pair[0]])
    if not abs(float(index.step[pair[1]]) - step) <= TIME_TO * step:
        return 0
    tolerance = SAME_TO * float(np.max(index.amplitude[list(pair)]))
    for match in matches:
        if not _stretch(short, long_, int(match) - anchor, tolerance, TIME_TO * step, around=anchor):
            continue  # a chance match: the samples next to it already differ
        shared = _stretch(short, long_, int(match) - anchor, tolerance, TIME_TO * step)
        if shared:
            return shared
    return 0


def _stretch(
    first: DecayRun, second: DecayRun, offset: int, tolerance: float, time_tolerance: float, around: int = -1
) -> int:
    """The samples shared with first's sample i on second's sample i + offset (0: they differ there);
    ``around`` >= 0: only the ``MIN_SHARED`` samples about first's sample ``around`` are compared."""
    lo, hi = max(0, -offset), min(first.t.size, second.t.size - offset)
    if hi - lo < MIN_SHARED:
        return 0
    if around >= 0:
        lo, hi = max(lo, around - MIN_SHARED // 2), min(hi, around + MIN_SHARED // 2)
    a, b = slice(lo, hi), slice(lo + offset, hi + offset)
    instants = (first.t[a] - first.t[lo]) - (second.t[b] - second.t[lo + offset])
    agree = np.max(np.abs(first.angle[a] - second.angle[b])) <= tolerance
    return hi - lo if agree and np.max(np.abs(instants)) <= time_tolerance else 0


def repeat_line(runs: Sequence[DecayRun], repeat: int, first: int) -> str:
    """What to say of a decay read twice."""
    left, kept = runs[repeat], runs[first]
    shared = shared_samples(left, kept)
    if shared == left.t.size == kept.t.size:
        what = f"is the same decay as {_label(kept)} (every sample agrees to {SAME_TO:g} of its amplitude)"
    else:
        seconds = shared * float(np.median(np.diff(left.t)))
        what = (
            f"holds {shared} of its {left.t.size} samples ({seconds:.1f} s) in common with {_label(kept)} "
            f"(each agrees to {SAME_TO:g} of the amplitude): a cut of the same decay"
        )
    return f"{_label(left)} {what}: one decay from two files, which would count twice"


def _label(run: DecayRun) -> str:
    file = run.meta.get("file")
    return f"{run.name} ({file})" if file and str(file) not in run.name else run.name
