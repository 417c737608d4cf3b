"""Whether a fitted decay is physically possible: checks every fit goes through before it is shown.

A least-squares fit always returns numbers; these checks say when physics forbids them, so that no
command, live view or session shows a confidently wrong answer. Each check is a pure function of the
coefficients and what was measured, and returns typed ``Implausibility``s whose ``message`` is one line: what
is wrong, the likely cause, what to do. docs/models.md ("Plausibility checks") lists every threshold
and why.

- damping: B_eq(phi_a) (ITTC eq. 15, ``derived.b_eq``) positive from rest to the largest tested
  amplitude: a passive hull loses energy at every amplitude; a B_eq below zero at small amplitude
  means the model would start rolling by itself (a limit cycle), the sign of linear and nonlinear
  damping trading off (b1 against b2/b3).
- stiffness: the restoring slope dr/dphi positive over the tested amplitudes (else the model capsizes
  inside the band it was fitted on).
- period: where the hull gives GM and a dry radius of gyration k, the natural period must agree with
  T = 2 pi k sqrt(1 + a) / sqrt(g GM) for an added inertia a of 5-40 % (typical for roll, reference
  §5), widened to ``ADDED_INERTIA_BOUNDS`` for GM and gyradius tolerances. Skipped, silently, without
  a gyradius.
- amplitude: the largest peak of a decay test lies between 0.5 and 45 deg (below: radians read as
  degrees, or no release; above: degrees read as radians, or a capsize).
- timing: the time step between 0.1 ms and 0.1 s, the natural period between 0.1 and 100 s and at
  least ten samples per period (a time column in milliseconds read as seconds fails all three).
- clipped: the angle flat at its extreme on two or more peaks for a tenth of a period or longer (a
  sensor's range or a stop; another lab's CSV carries no flags), or samples of the decay the sensor
  flagged (clipping, orientation not valid; ``DecayRun.excluded``) were left out of the fit: the result
  stands on the rest, and the decay was not a clean measurement. A finding about the data
  (``Finding.about_data``), not about the model: choosing a model ignores it.
- repeated: one decay among the fitted ones twice (two files holding the same samples, ``ident.repeats``):
  it would count as two repeats and narrow every interval. About the data too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..physics.decay import acceleration
from ..physics.terms import RESTORING_TERMS
from ..records import DecayRun
from .derived import G, b_eq, natural_period, tested_amplitudes_deg
from .repeats import repeat_line, repeated_decays
from .signals import white_noise_level

#: Peak angle of a decay test, deg: ITTC stops a decay at 0.5 deg; beyond 45 deg a model has capsized or
#: the angle is not in the unit it was read in.
AMPLITUDE_BOUNDS_DEG = (0.5, 45.0)
#: Time step, s: 10 kHz to 10 Hz (ITTC asks for at least 50 Hz; an MTi-G gives 100-400 Hz).
TIME_STEP_BOUNDS_S = (1e-4, 0.1)
#: Natural period, s: a model's roll or pitch (0.5-5 s) up to a full-scale ship's (up to about 30 s).
PERIOD_BOUNDS_S = (0.1, 100.0)
#: Fewer samples per natural period than this cannot resolve the oscillation.
MIN_SAMPLES_PER_PERIOD = 10
#: Added inertia as a fraction of the dry one: typically 5-40 % for roll (reference §5; KVLCC2 17 %),
#: widened by 0.1 and 0.15 for a gyradius known to about 5 % and GM to 2 % (k^2 / GM: about 12 %).
ADDED_INERTIA_BOUNDS = (-0.05, 0.55)
#: Checks about the measurement rather than the fitted model (every candidate model carries them alike).
DATA_CHECKS = ("clipped", "repeated")
#: A peak flat at the record's extreme for this fraction of a natural period is clipped (a peak is within
#: a coarse sensor's 0.1 deg step of its top for 4.5 % of a period at 10 deg; clipped 5 % below its top,
#: flat for 10 %).
FLAT_TOP_FRACTION = 0.1
#: A sample within this many noise levels of a flat top is on it: a clipped analog sensor's rail carries
#: the sensor's noise, so its top is no exact repeat of one value.
FLAT_TOP_NOISE = 4.0
#: Points of the amplitude grids the damping and stiffness checks look at.
GRID_POINTS = 41


@dataclass(frozen=True)
class Implausibility:
    """One implausibility: which check, the one-line message, the value and the bounds it broke."""

    check: str  # damping, stiffness, period, amplitude, time_step, clipped, repeated
    message: str
    value: float
    bounds: tuple[float, float]

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    @property
    def about_data(self) -> bool:
        """True for a finding about the measurement (clipped samples), which no model choice changes."""
        return self.check in DATA_CHECKS

    def __str__(self) -> str:
        return self.message


def check_damping(coefficients: Mapping[str, float], amplitude_rad: float) -> list[Implausibility]:
    """B_eq(phi_a) > 0 from rest (phi_a -> 0: B_eq = b1) to ``amplitude_rad``."""
    grid = np.linspace(0.0, max(amplitude_rad, 0.0), GRID_POINTS)
    values = np.array([b_eq(coefficients, float(a)) for a in grid])
    if not np.any(np.isfinite(values)):
        return []  # no positive stiffness: B_eq has no frequency; the stiffness check says so
    worst = int(np.nanargmin(values))
    if values[worst] > 0:
        return []
    where = f"{math.degrees(grid[worst]):.1f} deg"
    return [
        Implausibility(
            "damping",
            f"implausible damping: B_eq {values[worst]:.3g} 1/s at {where} is not positive (a passive hull "
            "loses energy at every amplitude); linear and nonlinear damping are trading off in this "
            "model: let the data choose the model (--model auto, the default) or fit more release "
            "angles together",
            float(values[worst]),
            (0.0, math.inf),
        )
    ]


def restoring_slope(coefficients: Mapping[str, float], angle_rad: np.ndarray) -> np.ndarray:
    """d r / d phi of the restoring terms at ``angle_rad`` (central differences, 1/s^2)."""
    restoring = {k: v for k, v in coefficients.items() if k in RESTORING_TERMS}
    step = 1e-6
    zero = np.zeros_like(angle_rad)
    forward = acceleration(restoring, angle_rad + step, zero)
    backward = acceleration(restoring, angle_rad - step, zero)
    return np.asarray(-(forward - backward) / (2 * step))


def check_stiffness(coefficients: Mapping[str, float], amplitude_rad: float) -> list[Implausibility]:
    """The restoring slope positive over +-``amplitude_rad``."""
    grid = np.linspace(-abs(amplitude_rad), abs(amplitude_rad), GRID_POINTS)
    slope = restoring_slope(coefficients, grid)
    worst = int(np.argmin(slope))
    if slope[worst] > 0:
        return []
    return [
        Implausibility(
            "stiffness",
            f"implausible restoring: slope {slope[worst]:.3g} 1/s^2 at {math.degrees(grid[worst]):+.1f} deg "
            "is not positive (the model would capsize inside the tested band); the cubic restoring is "
            "trading off against damping: let the data choose the model (--model auto) or fit more "
            "release angles",
            float(slope[worst]),
            (0.0, math.inf),
        )
    ]


def expected_period_s(gm_m: float, radius_of_gyration_m: float, added_fraction: float) -> float:
    """T = 2 pi k sqrt(1 + a) / sqrt(g GM): the natural period with added inertia fraction ``a``."""
    return 2 * math.pi * radius_of_gyration_m * math.sqrt(1 + added_fraction) / math.sqrt(G * gm_m)


def check_period(
    period_s: float,
    gm_m: float | None,
    radius_of_gyration_m: float | None,
    hull: str = "the hull",
    axis: str = "",
) -> list[Implausibility]:
    """The natural period against the hull's GM and gyradius; nothing without both."""
    if gm_m is None or radius_of_gyration_m is None or not gm_m > 0 or not math.isfinite(period_s):
        return []
    low, high = (expected_period_s(gm_m, radius_of_gyration_m, a) for a in ADDED_INERTIA_BOUNDS)
    if low <= period_s <= high:
        return []
    added = (period_s / expected_period_s(gm_m, radius_of_gyration_m, 0.0)) ** 2 - 1
    return [
        Implausibility(
            "period",
            f"natural period {period_s:.3g} s does not match {hull}{' ' + axis if axis else ''} "
            f"(GM {gm_m:g} m, gyradius {radius_of_gyration_m:g} m: {low:.3g}-{high:.3g} s, added inertia "
            f"{ADDED_INERTIA_BOUNDS[0]:.0%}-{ADDED_INERTIA_BOUNDS[1]:.0%}; this fit implies {added:.0%}): "
            "check the hull and draft given, the axis (roll or pitch) and the time unit",
            period_s,
            (low, high),
        )
    ]


def check_amplitude(amplitude_rad: float) -> list[Implausibility]:
    """The largest peak of the decay between ``AMPLITUDE_BOUNDS_DEG``."""
    amplitude_deg = math.degrees(abs(amplitude_rad))
    low, high = AMPLITUDE_BOUNDS_DEG
    if low <= amplitude_deg <= high:
        return []
    cause = (
        "radians read as degrees (give --angle-unit rad), or no release in the record"
        if amplitude_deg < low
        else "degrees read as radians (give --angle-unit deg), or the model capsized"
    )
    return [
        Implausibility(
            "amplitude",
            f"implausible amplitude: largest peak {amplitude_deg:.3g} deg, a decay test starts between "
            f"{low:g} and {high:g} deg; likely {cause}",
            amplitude_deg,
            (low, high),
        )
    ]


def check_timing(dt_s: float, period_s: float) -> list[Implausibility]:
    """Time step, natural period and samples per period inside their bounds."""
    found = []
    time_unit = "check the time unit (a column in milliseconds read as seconds)"
    if not TIME_STEP_BOUNDS_S[0] <= dt_s <= TIME_STEP_BOUNDS_S[1]:
        found.append(
            Implausibility(
                "time_step",
                f"implausible time step {dt_s:.3g} s (a decay is sampled at "
                f"{1 / TIME_STEP_BOUNDS_S[1]:g} Hz to {1 / TIME_STEP_BOUNDS_S[0]:g} Hz): {time_unit}",
                dt_s,
                TIME_STEP_BOUNDS_S,
            )
        )
    if math.isfinite(period_s) and not PERIOD_BOUNDS_S[0] <= period_s <= PERIOD_BOUNDS_S[1]:
        found.append(
            Implausibility(
                "period",
                f"implausible natural period {period_s:.3g} s (a model or ship rolls and pitches with "
                f"{PERIOD_BOUNDS_S[0]:g}-{PERIOD_BOUNDS_S[1]:g} s): {time_unit}",
                period_s,
                PERIOD_BOUNDS_S,
            )
        )
    elif math.isfinite(period_s) and dt_s > 0 and period_s / dt_s < MIN_SAMPLES_PER_PERIOD:
        found.append(
            Implausibility(
                "time_step",
                f"{period_s / dt_s:.2g} samples per natural period ({period_s:.3g} s at {dt_s:.3g} s): "
                f"too few to resolve the oscillation (at least {MIN_SAMPLES_PER_PERIOD}); {time_unit}",
                period_s / dt_s,
                (MIN_SAMPLES_PER_PERIOD, math.inf),
            )
        )
    return found


def check_excluded(runs: Sequence[DecayRun]) -> list[Implausibility]:
    """Runs with samples left out of the fit (``DecayRun.excluded``: the sensor clipped after the release,
    or its orientation was not valid): one finding each, with what the recording says of them."""
    found = []
    for run in runs:
        count = 0 if run.excluded is None else int(np.count_nonzero(run.excluded))
        if count:
            why = run.meta.get("excluded_why") or f"{count} samples flagged by the sensor: left out of fits"
            found.append(
                Implausibility(
                    "clipped",
                    f"{run.name}: {why}; the fit stands on the other samples, but the decay was not a clean "
                    "measurement: repeat it at a smaller angle (or with a sensor of wider range)",
                    float(count),
                    (0.0, 0.0),
                )
            )
    return found


def check_flat_tops(runs: Sequence[DecayRun], period_s: float) -> list[Implausibility]:
    """Runs whose angle sits at its largest (or smallest) level on two or more peaks, each for
    ``FLAT_TOP_FRACTION`` of a period or longer: clipped by the sensor's range or stopped by the rig, which
    no free decay does (the peaks of a decay shrink; a coarse sensor's steps flatten a peak for a few %
    of a period). The level is a value repeated, or held within ``FLAT_TOP_NOISE`` noise levels (a rail
    with the sensor's noise on it). For records no sensor flagged (another lab's CSV); one finding each."""
    found = []
    for run in runs:
        if run.angle.size < 3 or not math.isfinite(period_s):
            continue
        dt = float(np.median(np.diff(run.t)))
        tolerance = FLAT_TOP_NOISE * white_noise_level(run.angle)
        for sign in (1.0, -1.0):
            level, on_top = _top(sign * run.angle, tolerance)
            long = [n * dt for n in _plateaus(on_top) if n * dt >= FLAT_TOP_FRACTION * period_s]
            if len(long) >= 2:
                at_deg = math.degrees(sign * level)
                found.append(
                    Implausibility(
                        "clipped",
                        f"{run.name}: the angle is flat at {at_deg:+.2f} deg on {len(long)} "
                        f"peaks (up to {max(long):.2f} s, {100 * max(long) / period_s:.0f} % of a period): "
                        "clipped by the sensor's range or a stop; the fit does not see the true peaks: "
                        "record again with a wider range, or fit from after the clipping (--start S)",
                        float(len(long)),
                        (0.0, 1.0),
                    )
                )
                break
    return found


def _top(y: np.ndarray, tolerance: float) -> tuple[float, np.ndarray]:
    """The level of ``y``'s top and which samples are on it: its largest value repeated exactly, or, with
    noise (``tolerance`` > 0), the median of the samples near the largest, and those within ``tolerance``
    of it (the largest of a noisy rail stands a few noise levels above the rail itself)."""
    top = float(np.max(y))
    if tolerance <= 0:
        return top, y == top
    level = float(np.median(y[y >= top - 2.0 * tolerance]))
    return level, y >= level - tolerance


def _plateaus(mask: np.ndarray) -> list[int]:
    """The lengths of the runs of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1))


def check_fit(
    coefficients: Mapping[str, float],
    amplitude_rad: float,
    dt_s: float | None = None,
    particulars: Any = None,
    hull: str = "the hull",
) -> list[Implausibility]:
    """Every check of one fit. ``amplitude_rad``: the largest tested peak; ``dt_s``: the median time
    step (None: not checked); ``particulars``: the hull's ``config.AxisParticulars`` (GM, gyradius)."""
    period = natural_period(coefficients)
    found = check_amplitude(amplitude_rad)
    found += check_damping(coefficients, amplitude_rad)
    found += check_stiffness(coefficients, amplitude_rad)
    if dt_s is not None:
        found += check_timing(dt_s, period)
    if particulars is not None:
        found += check_period(
            period, particulars.gm_m, particulars.radius_of_gyration_m, hull, particulars.axis
        )
    return found


def check_runs(
    coefficients: Mapping[str, float],
    runs: Sequence[DecayRun],
    offsets: Sequence[float] | None = None,
    particulars: Any = None,
    hull: str = "the hull",
) -> list[Implausibility]:
    """``check_fit`` of a fit to ``runs``: the largest tested amplitude and the time step from the runs."""
    offsets = list(offsets) if offsets is not None else [0.0] * len(runs)
    amplitudes = tested_amplitudes_deg(runs, offsets)
    top = math.radians(max(amplitudes)) if amplitudes else max(float(np.max(np.abs(r.angle))) for r in runs)
    steps = np.concatenate([np.diff(run.t) for run in runs if run.t.size > 1] or [np.zeros(0)])
    dt_s = float(np.median(steps)) if steps.size else None
    checks = check_fit(coefficients, top, dt_s, particulars, hull) + check_excluded(runs)
    return checks + check_flat_tops(runs, natural_period(coefficients)) + check_repeats(runs)


def check_repeats(runs: Sequence[DecayRun]) -> list[Implausibility]:
    """One decay read twice among the fitted ones (``ident.repeats``): it counts as two repeats and
    narrows every interval. ``identify`` leaves such a copy out; a campaign's group says so here."""
    return [
        Implausibility(
            "repeated", f"{repeat_line(runs, i, first)}: leave one of the files out", 1.0, (0.0, 0.0)
        )
        for i, first in repeated_decays(runs).items()
    ]


def messages(findings: Sequence[Implausibility]) -> list[str]:
    """The findings' one-line messages, as warnings lists carry them."""
    return [finding.message for finding in findings]
