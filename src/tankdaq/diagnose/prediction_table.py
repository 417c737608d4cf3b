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

Ikeda's components beside the total (``B_F``, ``B_W``, ``B_E``, ``B_L``, ``B_BK``, as ``tankdaq predict``
names them) let the comparison say which of them would have to change to meet the measurement, as
tankdaq's own prediction does (``physics.ikeda.change_lines``). They are taken as shares of the damping
column at each amplitude, so their unit does not matter; beside a B̂44 column they must add up to it.
Components alone (no total) are B̂ values, as ``tankdaq predict`` prints them: their sum is the B̂44.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config.hulls import Hull
from ..errors import InputError
from ..ident.derived import G, b44_hat_factor
from ..physics.ikeda import COMPONENTS, change_lines, linear_quadratic_fit
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
#: Component columns (lower case) -> the key of Ikeda's component (``physics.ikeda.COMPONENTS``).
COMPONENT_COLUMNS = {key.lower(): key for key in COMPONENTS}
#: The damping column of a table of components alone: their sum, a B̂44.
SUM_OF_COMPONENTS = "b44_hat"
#: How far a table's components may be from its B̂44 column and still be its parts.
COMPONENTS_ADD_UP = 0.02
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
    return bool(names & set(AMPLITUDE_COLUMNS)) and bool(
        names & (set(DAMPING_COLUMNS) | set(COMPONENT_COLUMNS))
    )


@dataclass
class PredictionTable:
    """A damping table read: amplitudes (rad, sorted), the damping column's values and name, its
    components (``COMPONENT_COLUMNS``, row for row; may be empty), and the lines to say."""

    amplitudes_rad: np.ndarray
    damping: np.ndarray
    column: str
    components: dict[str, np.ndarray] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def read_prediction_table(path: Path) -> PredictionTable:
    """The table, its rows without a finite amplitude and damping left out (said); a table that cannot be
    a prediction is one line that says why."""
    table = read_table(path)
    columns = {name.lower(): values for name, values in table.columns.items()}
    amplitude_col = next((c for c in AMPLITUDE_COLUMNS if c in columns), None)
    damping_cols = [c for c in DAMPING_COLUMNS if c in columns]
    given = [name for name in COMPONENT_COLUMNS if name in columns]
    if not damping_cols and given:  # Ikeda's components alone (B̂, as ``tankdaq predict``): their sum
        columns[SUM_OF_COMPONENTS] = np.sum([columns[name] for name in given], axis=0)
        damping_cols = [SUM_OF_COMPONENTS]
    if amplitude_col is None or len(damping_cols) != 1:
        raise InputError(
            f"{path}: a prediction table needs one amplitude column ({', '.join(AMPLITUDE_COLUMNS)}) and one "
            f"damping column ({', '.join(DAMPING_COLUMNS)}) or Ikeda's components "
            f"({', '.join(COMPONENTS)}); it has {', '.join(table.columns)}"
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
    parts = {key: columns[name][keep][order] for name, key in COMPONENT_COLUMNS.items() if name in columns}
    found = PredictionTable(
        amplitudes[order], damping[order], damping_col, parts, said if not keep.all() else []
    )
    _check_components(found, path.name)
    return found


def _check_components(table: PredictionTable, source: str) -> None:
    """Components that cannot be the damping's parts are dropped, with the line that says why."""
    if not table.components:
        return
    values = np.array(list(table.components.values()))
    why = None
    if not np.all(np.isfinite(values)) or np.any(values < 0):
        why = "a component is missing or negative in some row"
    elif np.any(values.sum(axis=0) <= 0):
        why = "they add up to no damping in some row"
    elif DAMPING_COLUMNS[table.column] == HAT:
        off = float(np.max(np.abs(values.sum(axis=0) / table.damping - 1.0)))
        if off > COMPONENTS_ADD_UP:
            why = f"they do not add up to {table.column} (off by up to {off:.0%})"
    if why is not None:
        table.notes.append(f"{source}: its components ({', '.join(table.components)}) not used: {why}")
        table.components = {}


def component_changes(
    table: PredictionTable, b_eq: np.ndarray, omega: float
) -> Callable[[float, float, Sequence[float]], list[str]] | None:
    """The table's own account of a measured b1, b2: which of its components would have to change, and by
    how much (``physics.ikeda.change_lines``, over the table's amplitudes); None without components."""
    if not table.components:
        return None
    amplitudes, parts = component_parts(table, b_eq)

    def explain(b1: float, b2: float, _measured_amplitudes: Sequence[float]) -> list[str]:
        return change_lines(omega, list(amplitudes), parts, b1, b2)

    return explain


def component_parts(table: PredictionTable, b_eq: np.ndarray) -> tuple[list[float], list[dict[str, float]]]:
    """The table's distinct amplitudes (rad) and each component's share of B_eq / I (1/s) at each."""
    amplitudes, first = np.unique(table.amplitudes_rad, return_index=True)
    totals = np.sum(list(table.components.values()), axis=0)
    given = table.components
    parts = [
        {key: float(given[key][i] / totals[i] * b_eq[i]) if key in given else 0.0 for key in COMPONENTS}
        for i in first
    ]
    return list(amplitudes), parts


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
    b1, b2 = linear_quadratic_fit(omega, amplitudes_rad, b_eq)
    return {"b1": b1, "b2": b2, "c1": omega**2}


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
