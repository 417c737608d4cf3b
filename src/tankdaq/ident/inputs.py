"""Decays on the way in: the store reads a file, ident finds where its decays start.

``read_decays`` is the one entry point the fitting commands read files through (identify, diagnose,
campaign): ``store.inputs.read_runs`` picks the reader by suffix, and a record the store returned whole
(a plain CSV, ``FIND_RELEASES``) is cut here at its release, or split at each release when it holds
several. A decay is cut from the release, taken as the first extremum of large amplitude (a held tilt ends
where the model starts to move; a run driven to amplitude, like KVLCC2, starts at its first big peak). A
long record with several releases becomes several runs, as a recording with several release events does:
it is cut where the model rests at its equilibrium (stopped by hand, or settled), and within each part,
where a free decay ends by a new excitation, or dies into the noise with more to come, the rest is searched
for the next release (``ident.free_decay``; not after a carriage stop, which ends the test). Every part
that moves but holds no decay is named in a notice: a decay is found or reported, never dropped quietly.
This is signal work of identification, so it lives here and the store never imports ident.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..errors import BadIdentificationInput
from ..records import DecayRun
from ..store.csv_import import (
    DEFAULT_RATE_COL,
    FIND_RELEASES,
    MIN_SAMPLES,
    NOTICES,
    SPEED_CHANNEL,
    CsvOptions,
    number_parts,
)
from ..store.inputs import read_runs
from .free_decay import SPLIT_AFTER, find_free_end
from .signals import half_cycle_peaks, running_mean, running_range, white_noise_level

#: Fraction of the largest excursion a peak must reach to count as the release.
RELEASE_FRACTION = 0.5
#: A later release counts when its swing clears the noise by this factor.
NEXT_RELEASE_NOISES = 20.0
#: The model rests (stopped by hand, or settled) where the angle stays within this many noise sigmas
#: (peak to peak) for a natural period, near the equilibrium (``REST_LEVEL`` of the largest excursion).
REST_NOISES = 12.0
REST_LEVEL = 0.1


def read_decays(
    path: str | Path,
    axis: str | None = None,
    time_col: str = "time_s",
    angle_col: str = "angle_deg",
    rate_col: str | None = DEFAULT_RATE_COL,
    angle_unit: str | None = None,
    keep_all: bool = False,
    skip_half_cycles: int = 0,
    time_unit: str | None = None,
    sample_rate_hz: float | None = None,
    *,
    device: str | None = None,
    speed_col: str | None = None,
) -> list[DecayRun]:
    """The decays of one file, each from its release. The CSV settings (columns, units (None: decided
    from the data), ``keep_all``: the record whole from its first sample; ``skip_half_cycles`` more
    half-cycles dropped after a release found in the data; ``sample_rate_hz``: ``--rate``, for a text
    export that does not say its own) apply to CSV files; a recording's runs start at its release events.
    What the reading decided or left out is in each run's ``meta[NOTICES]`` (``input_notices``).
    ``device``: the device of an MT Manager log that holds several; ``speed_col``: a carriage-speed
    column, whose mean over each decay is its ``meta["speed_m_s"]``."""
    options = CsvOptions(
        time_col, angle_col, rate_col, angle_unit, keep_all, time_unit, sample_rate_hz, device, speed_col
    )
    try:
        return found_decays(read_runs(path, axis, options), skip_half_cycles)
    except BadIdentificationInput as exc:
        if not skip_half_cycles:
            raise
        raise BadIdentificationInput(
            f"{exc} (with {skip_half_cycles} half-cycles skipped: give fewer, --skip-half-cycles)"
        ) from None


def found_decays(runs: Iterable[DecayRun], skip_half_cycles: int = 0) -> list[DecayRun]:
    """Each run as its reader gave it, or, where the reader left the releases to the data (a CSV's
    record, ``FIND_RELEASES``), the decays found in it (``split_releases``); a decay with a carriage-speed
    channel (``--speed-col``) has its mean speed, to the cm/s, as ``meta["speed_m_s"]``."""
    decays = [
        decay
        for run in runs
        for decay in (split_releases(run, skip_half_cycles) if run.meta.pop(FIND_RELEASES, False) else [run])
    ]
    for decay in decays:
        if SPEED_CHANNEL in decay.channels:
            # to the cm/s, as a carriage is set: repeats at one speed are one condition (ident.conditions)
            decay.meta["speed_m_s"] = round(float(np.nanmean(decay.channels[SPEED_CHANNEL])), 2)
    return decays


def input_notices(runs: Iterable[DecayRun]) -> list[str]:
    """The reading's lines for the user (dialect, units, parts not used), each once, in order."""
    return list(dict.fromkeys(line for run in runs for line in run.meta.get(NOTICES, ())))


def split_releases(record: DecayRun, skip_half_cycles: int = 0) -> list[DecayRun]:
    """Every released decay in a record: the record is cut where the model rests at its equilibrium
    (stopped by hand or settled: ``rest_cuts``), and in each part the first release must exist, later
    ones where a free decay ends in a new excitation (or in the noise) and a swing well clear of the
    noise follows. A part that moves clear of the noise but holds no decay is named in a notice."""
    noise = white_noise_level(record.angle)
    runs: list[DecayRun] = []
    unused: list[str] = []
    failure: BadIdentificationInput | None = None
    bounds = [0, *rest_cuts(record.angle, noise), record.t.size]
    for a, b, c in zip(bounds[:-1], bounds[1:], [*bounds[2:], record.t.size], strict=True):
        part = record.window(a, b)
        if not _swings(part, noise):
            continue
        try:
            runs += _releases_in(record, (a, b, c), noise, skip_half_cycles)
        except BadIdentificationInput as exc:
            failure = failure or exc
            unused.append(f"{part.t[0]:.2f}..{part.t[-1]:.2f} s not used ({exc})")
    if not runs:
        raise failure or BadIdentificationInput(
            f"{record.meta.get('file', record.name)}: no decay found: the angle never swings clear of "
            "the noise"
        )
    lines = [f"{record.name}: {line}" for line in unused]
    if len(runs) > 1:
        starts = ", ".join(f"{run.t[0]:.1f}" for run in runs)
        lines.insert(0, f"{record.name}: {len(runs)} decays found, released at {starts} s")
    for run in runs:
        run.meta[NOTICES] = [*run.meta.get(NOTICES, ()), *lines]
    return number_parts(runs)


def rest_cuts(angle: np.ndarray, noise: float) -> list[int]:
    """Sample indices where the model rests at its equilibrium between decays: the middle of every
    stretch where a natural period around each sample stays within ``REST_NOISES`` noise sigmas, near
    the record's median (a held tilt is not a rest: it belongs to the release that follows)."""
    excursion = angle - np.median(angle)
    peaks = half_cycle_peaks(excursion)
    if peaks.size < 3 or noise <= 0:
        return []
    window = max(2 * int(np.median(np.diff(peaks))), 3)
    if angle.size < 3 * window:
        return []
    spread = running_range(angle, window)
    level = np.abs(running_mean(excursion, window))
    quiet = (spread < REST_NOISES * noise) & (level < REST_LEVEL * float(np.max(np.abs(excursion))))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], quiet.view(np.int8), [0]])))
    return [int((a + b) // 2) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _releases_in(
    record: DecayRun, bounds: tuple[int, int, int], noise: float, skip_half_cycles: int
) -> list[DecayRun]:
    """The releases in ``record[a:b]`` (a part between rests): the first, then one after each free
    decay that ends in a new excitation or in the noise with a swing to follow. Where a free decay
    ends is judged on the record up to ``c`` (through the next part): a model stopped by hand shows as
    a disturbance only against the swings after it. A run ended early says why in ``meta["split"]``."""
    a, b, c = bounds
    runs: list[DecayRun] = []
    start = a
    while True:
        try:
            release = start + release_index(record.angle[start:b], skip_half_cycles)
        except BadIdentificationInput:
            if not runs:
                raise
            break
        if b - release < MIN_SAMPLES:
            if not runs:
                raise BadIdentificationInput(f"{record.meta['file']}: too few samples left after the release")
            break
        end = find_free_end(record.window(release, c))
        stop = release + end.index
        more = end.kind in SPLIT_AFTER and b - stop >= MIN_SAMPLES and _swings(record.window(stop, b), noise)
        if stop >= b or not (more or c > b):  # the part's end, or the record's end: cut_free_decay's
            runs.append(record.window(release, b))
            break
        run = record.window(release, stop)
        run.meta["split"] = [end.kind, end.reason]
        runs.append(run)
        if not more:
            break
        start = stop
    return runs


def _swings(record: DecayRun, noise: float) -> bool:
    """The record moves well clear of the noise: a release may be in it."""
    return float(np.ptp(record.angle)) > NEXT_RELEASE_NOISES * max(noise, 1e-9)


def release_index(angle: np.ndarray, skip_half_cycles: int = 0) -> int:
    """Index of the release: the end of the first extremum reaching half the largest excursion.

    The equilibrium is the median of the last quarter (where the decay has
    settled). Within the first large half-wave the release is the last sample
    still within the noise (3 sigma) of its peak: the end of a held tilt, or
    just past the top of a peak.
    """
    excursion = angle - np.median(angle[-max(angle.size // 4, 1) :])
    peak = float(np.max(np.abs(excursion)))
    sign = np.sign(excursion)
    boundaries = np.concatenate([[0], np.flatnonzero(sign[1:] != sign[:-1]) + 1, [angle.size]])
    waves = [
        (a, b, float(np.max(np.abs(excursion[a:b]))))
        for a, b in itertools.pairwise(boundaries)
        if b < angle.size or int(np.argmax(np.abs(excursion[a:b]))) < b - a - 1  # it turns back: a swing
    ]
    tall = [i for i, (_, _, height) in enumerate(waves) if height >= RELEASE_FRACTION * peak]
    first = tall[0] if tall else len(waves)
    # a strongly damped decay may swing back only a little: any later half-wave clear of the noise counts
    swing = max(0.05 * peak, 5.0 * white_noise_level(angle))
    later = [w for w in waves[first:] if w[2] >= swing]
    if len(later) < 2 + skip_half_cycles:
        raise BadIdentificationInput(
            "no decay found: the record does not swing through equilibrium after its largest tilt"
        )
    large = [(a, b) for a, b, _ in later]
    a, b = large[skip_half_cycles]
    segment = np.abs(excursion[a:b])
    tolerance = 3.0 * white_noise_level(angle) + 1e-6 * segment.max()
    return int(a + np.flatnonzero(segment >= segment.max() - tolerance)[-1])
