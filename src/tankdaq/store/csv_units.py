"""The angle and time units of a CSV, decided from the data where the file does not say.

A spreadsheet column ``phi`` holding 0.18 is 10 deg in radians or 0.18 deg in degrees; a time column
counting to 63 000 is a minute in milliseconds. Read in the wrong unit, a decay still fits, to a
confidently wrong answer (c3 scaled by 3283, a period a thousand times long). The two readings of each
differ by a factor (57.3, 1000), so the data decide: a model decay swings by 0.5-45 deg
(``AMPLITUDE_DEG``) with a natural period of 0.3-60 s (``PERIOD_S``), sampled every 0.2 ms to 0.2 s
(``STEP_S``). Without a unit given, the one reading that is a decay wins, with one line saying so
(a column name ending ``_deg``/``_rad``/``_s``/``_ms``, or the unit a file states for the column,
breaks a tie); a unit given that makes no decay
while the other does, and a record no unit makes a decay of, are refused in one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

ANGLE_UNITS: dict[str, float] = {"deg": math.pi / 180.0, "rad": 1.0}
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "tick": 1e-4}
#: The time units the data may choose between. A column of an Xsens device's 10 kHz ticks (0.1 ms) reads as
#: milliseconds as plausibly (a 2.5 s period is 25 "s" in ms): only its name or --time-unit says tick.
DATA_TIME_UNITS = ("s", "ms")
#: Time columns that are an Xsens device's SampleTimeFine (MT Manager's export, a logger of the packets).
TICK_COLUMNS = ("sampletimefine",)
#: How other tools write those units in a file (an HDF5 ``unit`` attribute), lower case -> the unit.
UNIT_SPELLINGS = {
    **{name: "deg" for name in ("deg", "degree", "degrees", "\N{DEGREE SIGN}")},
    **{name: "rad" for name in ("rad", "radian", "radians")},
    **{name: "s" for name in ("s", "sec", "second", "seconds")},
    **{name: "ms" for name in ("ms", "millisecond", "milliseconds")},
    **{name: "tick" for name in ("tick", "ticks", "0.1 ms")},
}
#: A model decay's largest swing from equilibrium, deg (below it: sensor noise; above it: capsizing).
AMPLITUDE_DEG = (0.5, 45.0)
#: A model decay's natural period, s (a small model's pitch to a large model's roll).
PERIOD_S = (0.3, 60.0)
#: A decay record's sample step, s (5 kHz to 5 Hz).
STEP_S = (2e-4, 0.2)
#: Crossings of the equilibrium count once the swing clears this fraction of the largest excursion.
CROSSING_BAND = 0.2


@dataclass(frozen=True)
class UnitChoice:
    """The unit a column is read in and, when the data chose it, the one line that says why."""

    unit: str
    line: str | None = None


def stated_unit(text: object) -> str | None:
    """The angle or time unit a file's own unit text names (``UNIT_SPELLINGS``); None for any other."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    return UNIT_SPELLINGS.get(text.strip().lower()) if isinstance(text, str) else None


def amplitude(angle: np.ndarray) -> float:
    """The largest swing from the record's median (a stand-in for the equilibrium), in column units."""
    finite = angle[np.isfinite(angle)]
    return float(np.max(np.abs(finite - np.median(finite)))) if finite.size else 0.0


def period(t: np.ndarray, angle: np.ndarray) -> float | None:
    """The oscillation period in time-column units from the crossings of the median, each counted once
    the angle has left a band of ``CROSSING_BAND`` of the largest swing (noise does not cross); None
    with fewer than three crossings."""
    keep = np.isfinite(t) & np.isfinite(angle)
    if not keep.any():  # nothing to time (the caller says what is wrong with the columns)
        return None
    t, excursion = t[keep], angle[keep] - np.median(angle[keep])
    band = CROSSING_BAND * float(np.max(np.abs(excursion)))
    outside = np.flatnonzero(np.abs(excursion) > band)
    if band <= 0 or outside.size < 2:
        return None
    sides = np.sign(excursion[outside])
    crossings = t[outside[1:][sides[1:] != sides[:-1]]]
    if crossings.size < 3:
        return None
    return 2.0 * float(np.median(np.diff(crossings)))


def _suffix_unit(column: str, units: dict[str, float]) -> str | None:
    return next((unit for unit in units if column.lower().endswith(f"_{unit}")), None)


def angle_unit(column: str, angle: np.ndarray, given: str | None, stated: str | None = None) -> UnitChoice:
    """The unit of the angle column: ``given`` when it makes a decay (else refused), else decided; what
    the file says (``stated``, else the name's suffix) when both units would be a decay."""
    size = amplitude(angle)
    degrees = {unit: size * scale * 180.0 / math.pi for unit, scale in ANGLE_UNITS.items()}
    low, high = AMPLITUDE_DEG
    plausible = [unit for unit, deg in degrees.items() if low <= deg <= high]
    looks = (
        f"its largest swing is {size:.4g}: {degrees['deg']:.3g} deg read as degrees, "
        f"{degrees['rad']:.3g} deg read as radians"
    )
    if min(degrees.values()) > high:
        raise InputError(
            f"column {column!r} is no decay angle: {looks}; a model decay swings {low:g}-{high:g} deg "
            "(a scaled or wrong column?)"
        )
    if given is not None:
        if given not in ANGLE_UNITS:
            raise InputError(f"angle unit {given!r} not understood: use deg or rad")
        if given not in plausible and plausible:
            raise InputError(
                f"--angle-unit {given} makes column {column!r} swing {degrees[given]:.3g} deg, no model "
                f"decay ({low:g}-{high:g} deg); the data look like {plausible[0]} "
                f"({degrees[plausible[0]]:.3g} deg): use --angle-unit {plausible[0]} or leave it out"
            )
        return UnitChoice(given)
    named = stated or _suffix_unit(column, ANGLE_UNITS)
    if len(plausible) == 1:
        unit = plausible[0]
        said = None if unit == (named or "deg") else f"angle unit: {unit} ({column!r}: {looks}; "
        return UnitChoice(unit, said and said + f"only {unit} is a decay); --angle-unit overrides")
    unit = named or "deg"
    if plausible:  # both readings are decays: the name says, else degrees, and the user is told
        return UnitChoice(
            unit,
            f"angle unit: {unit}, but the other unit would be a decay too ({column!r}: {looks}); "
            "say --angle-unit",
        )
    return UnitChoice(unit)  # too small in either unit: the motion check speaks


def time_unit(
    column: str, t: np.ndarray, angle: np.ndarray, given: str | None, stated: str | None = None
) -> UnitChoice:
    """The unit of the time column: ``given`` when it makes a decay (else refused), else decided, as
    ``angle_unit`` is. A column that goes back in time is refused first: its period and step mean
    nothing (rows out of order)."""
    finite = t[np.isfinite(t)]
    back = np.flatnonzero(np.diff(finite) <= 0)
    if back.size:
        i = int(back[0])
        raise InputError(
            f"column {column!r} does not increase: sample {i + 2} ({finite[i + 1]:.6g}) is not after sample "
            f"{i + 1} ({finite[i]:.6g}); sort the rows by time, or check --time-col"
        )
    found = period(t, angle)
    steps = np.diff(t[np.isfinite(t)])
    step = float(np.median(steps)) if steps.size else math.nan
    named = stated or ("tick" if column.lower() in TICK_COLUMNS else _suffix_unit(column, TIME_UNITS))
    units = {unit: scale for unit, scale in TIME_UNITS.items() if unit in (*DATA_TIME_UNITS, named, given)}
    seconds = {unit: (found or math.nan) * scale for unit, scale in units.items()}
    step_s = {unit: step * scale for unit, scale in units.items()}
    low, high = PERIOD_S
    if found is not None:
        plausible = [unit for unit, value in seconds.items() if low <= value <= high]
        looks = f"the angle swings with a period of {found:.4g} time units"
        why = f"a model decay's period is {low:g}-{high:g} s"
    else:
        plausible = [unit for unit, value in step_s.items() if STEP_S[0] <= value <= STEP_S[1]]
        looks = f"a sample step of {step:.4g} time units"
        why = f"a decay is sampled every {STEP_S[0] * 1e3:g} ms to {STEP_S[1]:g} s"
    if given is not None:
        if given not in TIME_UNITS:
            raise InputError(f"time unit {given!r} not understood: use s, ms or tick (0.1 ms)")
        if given not in plausible and plausible:
            raise InputError(
                f"--time-unit {given} does not fit column {column!r}: {looks} ({why}); the data look like "
                f"{plausible[0]}: use --time-unit {plausible[0]} or leave it out"
            )
        return UnitChoice(given)
    if found is not None and not plausible:
        raise InputError(
            f"column {column!r} is no decay's time in s or ms: {looks} ({why}); check --time-col, "
            "or give --time-unit"
        )
    if len(plausible) == 1 and plausible[0] != (named or "s"):
        unit = plausible[0]
        line = f"time unit: {unit} ({column!r}: {looks}; {why}); --time-unit overrides"
        as_ticks = (found or math.nan) * TIME_UNITS["tick"]
        if unit == "ms" and low <= as_ticks <= high:  # the data cannot tell: said
            line += f" (in an Xsens device's 0.1 ms ticks the period is {as_ticks:.3g} s: --time-unit tick)"
        return UnitChoice(unit, line)
    if named == "tick" and named in plausible:  # said: a tick reads as ms as plausibly
        return UnitChoice("tick", f"time unit: tick, 0.1 ms ({column!r} is an Xsens SampleTimeFine)")
    return UnitChoice(plausible[0] if len(plausible) == 1 else named or "s")
