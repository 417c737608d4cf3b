"""Decay runs from CSV files (other labs' data, spreadsheets, the KVLCC2 reference run).

A decay is cut from the release, taken as the first extremum of large
amplitude (a held tilt ends where the model starts to move; a run driven to
amplitude, like KVLCC2, starts at its first big peak). A long record with
several releases becomes several runs, as a recording with several release
events does: where a free decay ends by a new excitation, or dies into the
noise with more to come, the rest of the file is searched for the next
release (``ident.free_decay``; not after a carriage stop, which ends the
test). A file written by ``tankdaq export`` (``store.export``) is read back
exactly: SI columns (``angle_rad``, ``rate_rad_s``) are taken without a
``--angle-col``, the units row is skipped, the ``# key = value`` block becomes
``meta`` and its ``release_t_s`` cuts the runs where the recording did. Extra
numeric columns become ``DecayRun.channels`` in SI units (``*_deg`` columns are
converted to rad and lose the suffix, so ``other_angle_deg`` -> ``other_angle``).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from pathlib import Path

import numpy as np

from ..errors import BadIdentificationInput, InputError
from ..ident.free_decay import SPLIT_AFTER, find_free_end
from ..ident.signals import white_noise_level
from ..records import DecayRun
from ..validation import input_file

ANGLE_UNITS: dict[str, float] = {"deg": math.pi / 180.0, "rad": 1.0}
#: Fraction of the largest excursion a peak must reach to count as the release.
RELEASE_FRACTION = 0.5
MIN_SAMPLES = 20
#: The rate column looked for by default; any other name given must exist.
DEFAULT_RATE_COL = "rate_deg_s"
#: The first line of a ``tankdaq export`` CSV (``store.export.CSV_MARK``).
EXPORT_MARK = "# tankdaq export"
#: A later release counts when its swing clears the noise by this factor.
NEXT_RELEASE_NOISES = 20.0


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
    """Read the decays of a CSV file; without the default rate column the angle is the only output.

    ``keep_all`` keeps the record whole from its first sample (one run); otherwise each run starts
    at a release, then ``skip_half_cycles`` more half-cycles are dropped.
    """
    path = Path(path)
    if angle_unit not in ANGLE_UNITS:
        raise InputError(f"angle unit {angle_unit!r} not understood: use deg or rad")
    if axis not in ("roll", "pitch"):
        raise InputError(f"axis {axis!r} not understood: use roll or pitch")
    columns, header = _read_columns(path)
    if angle_col == "angle_deg" and "angle_deg" not in columns and "angle_rad" in columns:  # SI (export)
        angle_col, angle_unit = "angle_rad", "rad"
        rate_col = "rate_rad_s" if rate_col == DEFAULT_RATE_COL else rate_col
    for label, name in (("time", time_col), ("angle", angle_col)):
        if name not in columns:
            raise InputError(
                f"{path}: no {label} column {name!r}; columns are {', '.join(columns)} "
                f"(choose with --{label}-col)"
            )
    if rate_col not in (None, DEFAULT_RATE_COL, "rate_rad_s") and rate_col not in columns:
        raise InputError(f"{path}: no rate column {rate_col!r}; columns are {', '.join(columns)}")
    to_rad = ANGLE_UNITS[angle_unit]
    t = columns.pop(time_col)
    angle = columns.pop(angle_col) * to_rad
    rate = columns.pop(rate_col) * to_rad if rate_col is not None and rate_col in columns else None
    channels = {_channel_name(name): _to_si(name, values) for name, values in columns.items()}
    run = DecayRun(
        t=t, angle=angle, rate=rate, axis=axis, name=path.stem, channels=channels, meta={"file": str(path)}
    )
    run.meta.update(header)
    _check_motion(run, angle_unit)
    if keep_all:
        runs = [run]
    elif header.get("release_t_s"):
        runs = _exported_releases(run, [float(r) for r in header["release_t_s"]])  # type: ignore[union-attr]
    else:
        runs = _releases(run, skip_half_cycles)
    for number, part in enumerate(runs, start=1):
        part.meta["initial_angle_rad"] = float(part.angle[0])
        if len(runs) > 1:
            part.name = f"{path.stem}#{number}"
    return runs


def _releases(record: DecayRun, skip_half_cycles: int) -> list[DecayRun]:
    """Every released decay in a record: the first must exist, later ones where a free decay ends in a
    new excitation (or in the noise) and a swing well clear of the noise follows."""
    noise = white_noise_level(record.angle)
    runs: list[DecayRun] = []
    rest = record
    while True:
        try:
            run = rest.window(release_index(rest.angle, skip_half_cycles))
        except BadIdentificationInput:
            if not runs:
                raise
            return runs
        if run.t.size < MIN_SAMPLES:
            if not runs:
                raise BadIdentificationInput(f"{record.meta['file']}: too few samples left after the release")
            return runs
        end = find_free_end(run)
        if end.kind not in SPLIT_AFTER or run.t.size - end.index < MIN_SAMPLES:
            return [*runs, run]
        later = run.window(end.index)
        if not _swings(later, noise):
            return [*runs, run]
        run = run.window(0, end.index)
        run.meta["split"] = [end.kind, end.reason]
        runs.append(run)
        rest = later


def _exported_releases(record: DecayRun, releases: list[float]) -> list[DecayRun]:
    """The runs of an exported recording: from each release to the next, as ``store.reader`` cuts them."""
    starts = np.searchsorted(record.t, [*releases, math.inf], side="left")
    return [record.window(int(a), int(b)) for a, b in itertools.pairwise(starts)]


def _swings(record: DecayRun, noise: float) -> bool:
    """The record moves well clear of the noise: a release may be in it."""
    return float(np.ptp(record.angle)) > NEXT_RELEASE_NOISES * max(noise, 1e-9)


def _read_columns(path: Path) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """The numeric columns, and the ``# key = value`` metadata block of a ``tankdaq export`` file."""
    input_file(path)
    try:
        with path.open(newline="") as fh:
            lines = [line for line in fh if line.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as CSV text ({exc})") from None
    header = _metadata(lines) if lines and lines[0].startswith(EXPORT_MARK) else {}
    rows = list(csv.reader(line for line in lines if not line.startswith("#")))
    if len(rows) > 1 and header and not _numeric(rows[1]):
        del rows[1]  # the units row of an export
    if len(rows) < 1 + MIN_SAMPLES:
        raise BadIdentificationInput(
            f"{path}: {max(len(rows) - 1, 0)} data rows; a decay needs at least {MIN_SAMPLES}"
        )
    names = [name.strip() for name in rows[0]]
    try:
        data = np.array([[float(cell) if cell.strip() else math.nan for cell in row] for row in rows[1:]])
    except ValueError as exc:
        raise InputError(f"{path}: a value is not a number ({exc}); only numeric columns are read") from None
    if data.ndim != 2 or data.shape[1] != len(names):
        raise InputError(f"{path}: rows have a different number of fields from the header")
    return {name: data[:, i] for i, name in enumerate(names)}, header


def _metadata(lines: list[str]) -> dict[str, object]:
    """``# key = <JSON>`` comment lines; a value that is not JSON stays text."""
    meta: dict[str, object] = {}
    for line in lines:
        if not line.startswith("#"):
            break
        key, sep, value = line[1:].partition(" = ")
        if sep:
            try:
                meta[key.strip()] = json.loads(value)
            except json.JSONDecodeError:
                meta[key.strip()] = value.strip()
    return meta


def _numeric(row: list[str]) -> bool:
    try:
        [float(cell) for cell in row if cell.strip()]
    except ValueError:
        return False
    return True


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
