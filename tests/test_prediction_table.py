"""A roll-damping prediction made elsewhere, given to ``diagnose --simulation`` as a table of damping
against amplitude: the same decay model as tankdaq's own ``ikeda`` prediction when the table holds that
prediction's values, in any of its three damping columns; a table that cannot be a prediction is one line.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.config import ikeda_prediction, load_hull
from tankdaq.diagnose.simulation import SimulationRequest, dominant_period_s, resolve_simulation
from tankdaq.errors import InputError
from tankdaq.ident.campaign_synthetic import write_simulated_campaign
from tankdaq.ident.free_decay import cut_free_decays
from tankdaq.ident.inputs import read_decays

KVLCC2 = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)
#: Each damping column of a table -> the key of ``tankdaq predict --json``'s rows that holds it.
COLUMNS = {"b_eq_per_s": "b_eq_per_s", "b44_n_m_s": "b44_n_m_s", "b44_hat": "B_44", "B_44": "B_44"}


def _table(path: Path, header: list[str], rows: list[list[float]]) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


@pytest.mark.skipif(not KVLCC2.is_file(), reason=f"the KVLCC2 roll decay is not at {KVLCC2}")
@pytest.mark.parametrize("column", list(COLUMNS))
def test_a_table_of_the_ikeda_prediction_is_that_prediction(tmp_path: Path, column: str) -> None:
    """The shipped KVLCC2 hull's simplified-Ikeda values, written as another tool would (2-12 deg), give
    the model ``--simulation ikeda`` gives for run 21338."""
    runs = cut_free_decays(read_decays(KVLCC2, "roll", "time", "phi", None, "rad"), None, None)
    hull = load_hull("kvlcc2")
    request = SimulationRequest(tuple(runs), "roll", hull, 1.0)
    prediction = ikeda_prediction(hull, 1.0, period_s=dominant_period_s(runs))
    rows = prediction.summary([math.radians(a) for a in (2, 4, 6, 8, 10, 12)])["amplitudes"]
    table = _table(
        tmp_path / "ikeda_sheet.csv",
        ["amplitude_deg", column],
        [[r["amplitude_deg"], r[COLUMNS[column]]] for r in rows],
    )
    from_table, own = resolve_simulation([str(table)], request), resolve_simulation(["ikeda"], request)
    assert from_table.kind == own.kind == "prediction"
    for term in ("b1", "b2", "c1"):
        assert from_table.coefficients[term] == pytest.approx(own.coefficients[term], rel=1e-6), term
    measured_start = max(abs(math.degrees(float(run.angle[0]))) for run in runs)
    assert measured_start < 12  # inside the table: no extrapolation is said
    assert not any("extrapolated" in note for note in from_table.notes)


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A swath roll decay at 8 deg, as a lab's CSV."""
    (path,) = write_simulated_campaign(tmp_path_factory.mktemp("m"), ["swath"], "roll", [1.0], [8.0], "csv")
    return path


def test_a_table_reaching_less_far_than_the_decays_says_it_extrapolates(
    measured: Path, tmp_path: Path
) -> None:
    runs = cut_free_decays(read_decays(measured), None, None)
    rows = [[2.0, 0.3], [3.0, float("inf")], [4.0, 0.35]]  # a cell of 1e400 reads as inf
    table = _table(tmp_path / "p.csv", ["Amplitude_deg", "b_eq_per_s"], rows)
    simulation = resolve_simulation([str(table)], SimulationRequest(tuple(runs)))
    omega = 2 * math.pi / dominant_period_s(runs)
    assert simulation.coefficients["b2"] == pytest.approx(
        0.05 / (8 / (3 * math.pi) * omega * math.radians(2))
    )
    assert any("the table covers 2-4 deg" in note and "extrapolated" in note for note in simulation.notes)
    assert "p.csv: 1 row(s) without a finite amplitude and b_eq_per_s left out" in simulation.notes


@pytest.mark.parametrize(
    ("header", "rows", "extra", "said"),
    [
        (["amplitude_deg", "b_eq_per_s"], [[2, 0.3], [4, -0.1]], [], "no or negative damping"),
        (["amplitude_deg", "b_eq_per_s"], [[0.035, 0.3], [0.07, 0.35]], [], "check the column's unit"),
        (["amplitude_deg", "b44_n_m_s"], [[2, 0.3], [4, 0.35]], [], "needs --hull NAME"),
        (["amplitude_deg", "b_eq_per_s", "b44_hat"], [[2, 0.3, 0.01]], [], "one damping column"),
        (["amplitude_deg", "b_eq_per_s"], [[2, 0.3]], ["other.csv"], "stands alone"),
    ],
)
def test_a_table_that_cannot_be_a_prediction_is_one_line(
    measured: Path, tmp_path: Path, header: list[str], rows: list[list[float]], extra: list[str], said: str
) -> None:
    table = _table(tmp_path / "p.csv", header, rows)
    args = ["diagnose", str(measured), "--simulation", str(table), "--catalogue", "none"]
    for name in extra:
        args += ["--simulation", str(_table(tmp_path / name, ["t", "x"], [[0, 1]]))]
    result = CliRunner().invoke(app, args)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and said in lines[0], lines


def test_a_single_amplitude_gives_linear_damping_alone(measured: Path, tmp_path: Path) -> None:
    runs = cut_free_decays(read_decays(measured), None, None)
    table = _table(tmp_path / "one.csv", ["phi_a_rad", "b_eq_per_s"], [[0.1, 0.42]])
    simulation = resolve_simulation([str(table)], SimulationRequest(tuple(runs)))
    assert (simulation.coefficients["b1"], simulation.coefficients["b2"]) == (0.42, 0.0)
    with pytest.raises(InputError, match="roll prediction"):
        resolve_simulation([str(table)], SimulationRequest(tuple(runs), axis="pitch"))
    assert np.isfinite(simulation.coefficients["c1"])
