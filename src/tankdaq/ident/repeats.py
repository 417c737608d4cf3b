"""One decay read twice from two files: the same samples, whatever the files' bytes.

A lab's folder holds a run's CSV and the same run re-saved by a spreadsheet (other decimals, another
separator, degrees where the first had radians), or a copy in a colleague's "selected" folder. The
files differ, so neither their hashes nor an export's metadata tell (``store.inputs.read_twice``); their
decays, read, are the same. Fitted together such a decay counts as two repeats: every interval narrows
by √2 for nothing. Two decays are one when they have as many samples, the same sampling instants (to
``TIME_TO`` of a step) and angles that agree to ``SAME_TO`` of the decay's amplitude: two real decays
never do, their noise alone differs by more (a sensor's 0.01 deg is 1e-3 of a 10 deg decay).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence

import numpy as np

from ..records import DecayRun

#: Two decays whose angles agree to this fraction of their amplitude, sample by sample, are one (a CSV
#: re-saved with four significant digits still agrees to 1e-4).
SAME_TO = 2e-4
#: ...and whose sampling instants, from each one's start, agree to this fraction of a time step.
TIME_TO = 0.1


def same_decay(first: DecayRun, second: DecayRun) -> bool:
    """True when ``second`` holds ``first``'s samples (instants from its start to ``TIME_TO`` of a step,
    angles to ``SAME_TO`` of the amplitude)."""
    if first.t.size != second.t.size or first.t.size < 2:
        return False
    amplitude = float(np.max(np.abs(first.angle)))
    step = float(np.median(np.diff(first.t)))
    instants = np.max(np.abs((first.t - first.t[0]) - (second.t - second.t[0])))
    if amplitude <= 0 or not instants <= TIME_TO * step:  # a time column saved to fewer digits still agrees
        return False
    return bool(np.max(np.abs(first.angle - second.angle)) <= SAME_TO * amplitude)


def repeated_decays(runs: Sequence[DecayRun]) -> dict[int, int]:
    """Index of each decay that repeats an earlier one -> the index of that one."""
    earlier: dict[int, list[int]] = defaultdict(list)  # by sample count: only those can be one
    repeats: dict[int, int] = {}
    for i, run in enumerate(runs):
        bucket = earlier[run.t.size]
        first = next((j for j in bucket if same_decay(runs[j], run)), None)
        if first is None:
            bucket.append(i)
        else:
            repeats[i] = first
    return repeats


def repeat_line(runs: Sequence[DecayRun], repeat: int, first: int) -> str:
    """What to say of a decay read twice."""
    return (
        f"{_label(runs[repeat])} is the same decay as {_label(runs[first])} (every sample agrees to "
        f"{SAME_TO:g} of its amplitude): one decay from two files, which would count twice"
    )


def _label(run: DecayRun) -> str:
    file = run.meta.get("file")
    return f"{run.name} ({file})" if file and str(file) not in run.name else run.name
