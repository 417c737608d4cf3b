"""A roll-damping prediction made elsewhere, given as a table: the equivalent linear damping at each roll
amplitude (an Ikeda spreadsheet's, a seakeeping code's B44 against amplitude), made a decay model as
tankdaq's own ``ikeda`` prediction is (``simulation.from_ikeda``).

A CSV (any dialect ``identify`` reads) with an amplitude column and one damping column, named as
``tankdaq predict --json`` names them (case aside):

- the amplitude: ``amplitude_deg`` or ``amplitude_rad`` (``phi_a_deg``, ``phi_a_rad`` too);
- the damping: ``b_eq_per_s`` (B_eq / I, 1/s), ``b44_hat`` or ``b_44`` (B̂44 = B44 / (ρ ∇ B²) · √(B / 2g):
  needs the hull's beam and displacement) or ``b44_n_m_s`` (N·m·s: needs the hull's displacement and GM,
  for I = Δ g GM / c1 with c1 from the measured period).

A prediction gives damping, not stiffness: it is evaluated at the measured period, and B_eq / I =
b1 + 8/(3π) ω φa b2 is fitted over the table's amplitudes (``ident.derived.b_eq``'s convention).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..config import Hull
from ..errors import InputError
from ..ident.derived import G, b44_hat_factor
from ..store.csv_dialect import read_table

PER_INERTIA, HAT, DIMENSIONAL = "B_eq / I", "B̂44", "B44"
#: Amplitude columns (lower case) -> radians per unit.
AMPLITUDE_COLUMNS = {
    "amplitude_deg": math.pi / 180.0,
    "phi_a_deg": math.pi / 180.0,
    "amplitude_rad": 1.0,
    "phi_a_rad": 1.0,
}
#: Damping columns (lower case) -> what they hold: B_eq per unit inertia (1/s), B̂44, or B44 (N·m·s).
DAMPING_COLUMNS = {"b_eq_per_s": PER_INERTIA, "b44_hat": HAT, "b_44": HAT, "b44_n_m_s": DIMENSIONAL}
#: Amplitudes a decay test reaches (rad): a table outside them is a unit slip.
AMPLITUDE_RANGE_RAD = (math.radians(0.1), math.radians(60.0))


def is_prediction_table(path: Path) -> bool:
    """A CSV whose header names an amplitude and a damping column (and so is no time series)."""
    if path.suffix.lower() != ".csv" or not path.is_file():
        return False
    try:
        with path.open("rb") as fh:
            head = fh.readline(4096).decode("utf-8-sig", "replace").lower()
    except OSError:
        return False
    names = {name.strip().strip('"') for separator in ",;\t" for name in head.split(separator)}
    return bool(names & set(AMPLITUDE_COLUMNS)) and bool(names & set(DAMPING_COLUMNS))


def read_prediction_table(path: Path) -> tuple[np.ndarray, np.ndarray, str, list[str]]:
    """Amplitudes (rad), the damping values, their column's name, sorted by amplitude, and the lines to
    say (rows left out); a table that cannot be a prediction is one line that says why."""
    table = read_table(path)
    columns = {name.lower(): values for name, values in table.columns.items()}
    amplitude_col = next((c for c in AMPLITUDE_COLUMNS if c in columns), None)
    damping_cols = [c for c in DAMPING_COLUMNS if c in columns]
    if amplitude_col is None or len(damping_cols) != 1:
        raise InputError(
            f"{path}: a prediction table needs one amplitude column ({', '.join(AMPLITUDE_COLUMNS)}) and one "
            f"damping column ({', '.join(DAMPING_COLUMNS)}); it has {', '.join(table.columns)}"
        )
    (damping_col,) = damping_cols
    amplitudes = columns[amplitude_col] * AMPLITUDE_COLUMNS[amplitude_col]
    damping = columns[damping_col]
    keep = np.isfinite(amplitudes) & np.isfinite(damping)
    if keep.sum() < 1:
        raise InputError(f"{path}: no row with a finite amplitude and {damping_col}")
    said = [f"{path.name}: {int((~keep).sum())} row(s) without a finite amplitude and {damping_col} left out"]
    amplitudes, damping = amplitudes[keep], damping[keep]
    low, high = AMPLITUDE_RANGE_RAD
    if amplitudes.min() < low or amplitudes.max() > high:
        raise InputError(
            f"{path}: {amplitude_col} spans {_deg(amplitudes.min())}-{_deg(amplitudes.max())} deg, no decay "
            f"test's ({_deg(low)}-{_deg(high)} deg): check the column's unit"
        )
    if np.any(damping <= 0):
        raise InputError(
            f"{path}: {damping_col} is not above 0 at every amplitude: no or negative damping is no roll "
            "damping prediction; check the column"
        )
    order = np.argsort(amplitudes)
    return amplitudes[order], damping[order], damping_col, said if not keep.all() else []


def per_unit_inertia(
    damping: np.ndarray, column: str, hull: Hull | None, draft: float, axis: str, c1: float, source: str
) -> tuple[np.ndarray, str | None]:
    """The damping as B_eq / I (1/s), and how it was converted (None when it already was)."""
    kind = DAMPING_COLUMNS[column]
    if kind == PER_INERTIA:
        return damping, None
    if hull is None:
        raise InputError(f"--simulation {source}: its {column} needs --hull NAME (and --draft) to convert it")
    inertia = _total_inertia(hull, draft, axis, c1, source)
    if kind == DIMENSIONAL:
        return damping / inertia, f"B44 / I with I = displacement g GM / c1 = {inertia:.4g} kg m^2"
    factor = b44_hat_factor(hull, draft)
    if factor is None:
        raise InputError(f"--simulation {source}: its {column} needs the hull's beam_m and displacement_kg")
    return damping / factor / inertia, f"B̂44 / (B̂44 per B44 {factor:.4g}) / I, I = {inertia:.4g} kg m^2"


def _total_inertia(hull: Hull, draft: float, axis: str, c1: float, source: str) -> float:
    gm, displacement = hull.particulars(axis).gm_m, hull.displacement_kg
    if gm is None or displacement is None:
        raise InputError(f"--simulation {source}: the hull needs displacement_kg and the {axis} gm_m")
    return float(displacement * draft * G * gm / c1)


def equivalent_model(amplitudes_rad: np.ndarray, b_eq: np.ndarray, omega: float) -> dict[str, float]:
    """{"b1", "b2", "c1"}: B_eq / I = b1 + 8/(3π) ω φa b2 least-squares over the rows (one row: b1
    alone), c1 = ω² (the measured period: a prediction gives damping, not stiffness)."""
    if np.unique(amplitudes_rad).size < 2:
        return {"b1": float(np.mean(b_eq)), "b2": 0.0, "c1": omega**2}
    design = np.column_stack([np.ones_like(amplitudes_rad), 8.0 / (3.0 * math.pi) * omega * amplitudes_rad])
    (b1, b2), *_ = np.linalg.lstsq(design, b_eq, rcond=None)
    return {"b1": float(b1), "b2": float(b2), "c1": omega**2}


def coverage_note(amplitudes_rad: np.ndarray, measured_rad: Sequence[float]) -> str | None:
    """A line when the measured amplitudes reach outside the table's (the model extrapolates there)."""
    low, high = float(amplitudes_rad.min()), float(amplitudes_rad.max())
    outside = [a for a in measured_rad if not low * 0.999 <= a <= high * 1.001]
    if not outside:
        return None
    return (
        f"the table covers {_deg(low)}-{_deg(high)} deg; measured decays start at "
        f"{', '.join(_deg(a) for a in outside)} deg: there the prediction is extrapolated"
    )


def _deg(angle_rad: float) -> str:
    return f"{math.degrees(angle_rad):.3g}"
