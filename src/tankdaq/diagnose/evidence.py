"""An effect is named only on its own evidence: rig friction by its signature, a coupling by its channel.

A fit improves when a term bends it toward the measurement, whatever the term means: over a decay at
speed, dry friction (B_eq ∝ 1/φa) fits a prediction's missing lift damping at small amplitude, and a
recorded heave moving at twice the roll frequency fits a damping that is simply off. So before the
comparison offers such an effect, the measurement must show what only that effect leaves:

- rig friction: a decrement per half cycle that stays constant as the amplitude falls (the extinction
  curve's intercept at φm -> 0, reference §8, which a viscous decay reaching the noise does not show)
  and a dead band at the end: the swing stops inside the record (a record that ends still swinging
  shows none, and friction is not named from it);
- a coupling: the other channel recorded in every run and moving with the roll at the roll frequency
  (magnitude-squared coherence above ``COHERENCE``).

Where the evidence is absent the effect is withheld and said so; the comparison then says what differs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import coherence

from ..ident.signals import half_cycle_peaks
from ..records import DecayRun

#: The extinction curve's intercept must be this share of the decrement at the smallest tested amplitude,
INTERCEPT_SHARE = 0.5
#: and this many standard errors above zero.
INTERCEPT_SIGMAS = 3.0
#: A channel moves with the roll when their coherence at the roll frequency is above this.
COHERENCE = 0.5
#: The swing has stopped when the record goes on this many periods after its last half cycle.
STOPPED_PERIODS = 2.0


@dataclass(frozen=True)
class Evidence:
    """Whether an effect's own signature is in the measurement, and the line that says what was seen."""

    seen: bool
    line: str


def _peaks(run: DecayRun) -> tuple[np.ndarray, np.ndarray]:
    """Times and absolute values of the run's half-cycle peaks (about its median)."""
    y = run.angle - float(np.median(run.angle))
    idx = half_cycle_peaks(y)
    return run.t[idx], np.abs(y[idx])


def _intercept(runs: Sequence[DecayRun]) -> tuple[float, float, float] | None:
    """(intercept, its standard error, the decrement at the smallest mean amplitude) of the extinction
    curve d = a + b φm + c φm² (least squares, all runs' half cycles pooled); None with too few."""
    means, drops = [], []
    for run in runs:
        _, peaks = _peaks(run)
        means.append(0.5 * (peaks[:-1] + peaks[1:]))
        drops.append(peaks[:-1] - peaks[1:])
    m, d = np.concatenate(means), np.concatenate(drops)
    if m.size < 6:
        return None
    design = np.column_stack([np.ones_like(m), m, m**2])
    coef, *_ = np.linalg.lstsq(design, d, rcond=None)
    residual = d - design @ coef
    sigma2 = float(residual @ residual) / max(m.size - 3, 1)
    covariance = sigma2 * np.linalg.pinv(design.T @ design)
    return float(coef[0]), math.sqrt(max(covariance[0, 0], 0.0)), float(design[np.argmin(m)] @ coef)


def _stops(run: DecayRun) -> bool:
    """Whether the swing stops inside the record: no half cycle outside the noise band (3 sigma, as
    ``half_cycle_peaks`` takes it) for the last ``STOPPED_PERIODS`` periods of the record."""
    times, peaks = _peaks(run)
    if peaks.size < 4:
        return False
    period = 2.0 * float(np.median(np.diff(times)))
    return bool(run.t[-1] - times[-1] > STOPPED_PERIODS * period)


def friction_evidence(runs: Sequence[DecayRun]) -> Evidence:
    """Rig friction's signature in the measured decays (a constant decrement at small amplitude, and the
    swing stopping in a dead band), with the line that says what was and was not seen."""
    found = _intercept(runs)
    if found is None:
        return Evidence(False, "too few half cycles for the extinction curve")
    a, se, smallest = found
    constant = a > INTERCEPT_SIGMAS * se and smallest > 0 and a >= INTERCEPT_SHARE * smallest
    what = (
        f"extinction-curve intercept {math.degrees(a):.3g} deg per half cycle (+-{math.degrees(se):.2g}), "
        f"{100 * a / smallest:.0f} % of the decrement at the smallest amplitude"
        if smallest > 0
        else "no decrement at the smallest amplitude"
    )
    stopped = [_stops(run) for run in runs]
    tail = (
        "the swing stops inside the record (a dead band)"
        if any(stopped)
        else "the record ends still swinging: no dead band seen"
    )
    seen = constant and any(stopped)
    verdict = "rig friction's signature" if seen else "no rig friction's signature"
    return Evidence(seen, f"{verdict}: {what}; {tail}")


def coupling_evidence(runs: Sequence[DecayRun], channel: str | None, omega_rad_s: float) -> Evidence:
    """Whether ``channel`` is recorded in every run and coherent with the roll at its frequency."""
    if channel is None:
        return Evidence(False, "no channel of the other motion is recorded in every run")
    values = []
    for run in runs:
        rate = run.sample_rate
        segment = min(run.t.size, max(int(8 * 2 * math.pi / omega_rad_s * rate), 16))
        freqs, gamma2 = coherence(run.angle, run.channels[channel], fs=rate, nperseg=segment // 2)
        values.append(float(np.interp(omega_rad_s / (2 * math.pi), freqs, gamma2)))
    value = float(np.mean(values))
    seen = value > COHERENCE
    moves = "moves" if seen else "does not move"
    return Evidence(
        seen,
        f"{channel} {moves} with the roll at the roll frequency (coherence {value:.2f}, "
        f"threshold {COHERENCE:g})",
    )
