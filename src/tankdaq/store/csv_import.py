"""Decay runs from CSV files (other labs' data, spreadsheets, the KVLCC2 reference run).

One file is one run. The decay is cut from the release, taken as the first
extremum of large amplitude (a held tilt ends where the model starts to move;
a run driven to amplitude, like KVLCC2, starts at its first big peak). Extra
numeric columns become ``DecayRun.channels`` in SI units (``*_deg`` columns are
converted to rad and lose the suffix, so ``other_angle_deg`` -> ``other_angle``).
"""

from __future__ import annotations

import csv
import itertools
import math
from pathlib import Path

import numpy as np

from ..errors import BadIdentificationInput, InputError
from ..ident.signals import white_noise_level
from ..records import DecayRun
from ..validation import input_file

ANGLE_UNITS: dict[str, float] = {"deg": math.pi / 180.0, "rad": 1.0}
#: Fraction of the largest excursion a peak must reach to count as the release.
RELEASE_FRACTION = 0.5
MIN_SAMPLES = 20
#: The rate column looked for by default; any other name given must exist.
DEFAULT_RATE_COL = "rate_deg_s"


def read_csv_runs(
    path: str | Path,
    time_col: str = "time_s",
    angle_col: str = "angle_deg",
    rate_col: str | None = DEFAULT_RATE_COL,
    angle_unit: str = "deg",
    axis: str = "roll",
    keep_all: bool = False,
    skip_half_cycles: int = 0,
) -> list[DecayRun]:
    """Read one decay from a CSV file; without the default rate column the angle is the only output.

    ``keep_all`` keeps the record from its first sample; otherwise it starts at
    the release, then ``skip_half_cycles`` more half-cycles are dropped.
    """
    path = Path(path)
    if angle_unit not in ANGLE_UNITS:
        raise InputError(f"angle unit {angle_unit!r} not understood: use deg or rad")
    if axis not in ("roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
    columns = _read_columns(path)
    for label, name in (("time", time_col), ("angle", angle_col)):
        if name not in columns:
            raise InputError(
                f"{path}: no {label} column {name!r}; columns are {', '.join(columns)} "
                f"(choose with --{label}-col)"
            )
    if rate_col not in (None, DEFAULT_RATE_COL) and rate_col not in columns:
        raise InputError(f"{path}: no rate column {rate_col!r}; columns are {', '.join(columns)}")
    to_rad = ANGLE_UNITS[angle_unit]
    t = columns.pop(time_col)
    angle = columns.pop(angle_col) * to_rad
    rate = columns.pop(rate_col) * to_rad if rate_col is not None and rate_col in columns else None
    channels = {_channel_name(name): _to_si(name, values) for name, values in columns.items()}
    run = DecayRun(
        t=t, angle=angle, rate=rate, axis=axis, name=path.stem, channels=channels, meta={"file": str(path)}
    )
    _check_motion(run, angle_unit)
    if not keep_all:
        run = run.window(release_index(run.angle, skip_half_cycles))
        if run.t.size < MIN_SAMPLES:
            raise BadIdentificationInput(f"{path}: too few samples left after the release")
    run.meta["initial_angle_rad"] = float(run.angle[0])
    return [run]


def _read_columns(path: Path) -> dict[str, np.ndarray]:
    input_file(path)
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(line for line in fh if line.strip() and not line.startswith("#")))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as CSV text ({exc})") from None
    if len(rows) < 1 + MIN_SAMPLES:
        raise BadIdentificationInput(
            f"{path}: {max(len(rows) - 1, 0)} data rows; a decay needs at least {MIN_SAMPLES}"
        )
    header = [name.strip() for name in rows[0]]
    try:
        data = np.array([[float(cell) if cell.strip() else math.nan for cell in row] for row in rows[1:]])
    except ValueError as exc:
        raise InputError(f"{path}: a value is not a number ({exc}); only numeric columns are read") from None
    if data.ndim != 2 or data.shape[1] != len(header):
        raise InputError(f"{path}: rows have a different number of fields from the header")
    return {name: data[:, i] for i, name in enumerate(header)}


def _channel_name(column: str) -> str:
    for suffix in ("_deg", "_rad"):
        if column.endswith(suffix):
            return column[: -len(suffix)]
    return column


def _to_si(column: str, values: np.ndarray) -> np.ndarray:
    return values * ANGLE_UNITS["deg"] if column.endswith("_deg") else values


def _check_motion(run: DecayRun, angle_unit: str) -> None:
    """An axis that does not move gives a clear message instead of a failed fit."""
    span_deg = math.degrees(float(np.ptp(run.angle)))
    if span_deg < 0.05:
        raise BadIdentificationInput(
            f"{run.name}: the {run.axis} angle does not move (range {span_deg:.3g} deg); "
            f"wrong axis or wrong column? (angle unit {angle_unit})"
        )


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
