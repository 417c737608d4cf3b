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

from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.cli import app
from tankdaq.config.hulls import ikeda_prediction, load_hull
from tankdaq.diagnose.simulation import SimulationRequest, dominant_period_s, resolve_simulation
from tankdaq.errors import InputError
from tankdaq.ident.free_decay import cut_free_decays
from tankdaq.ident.inputs import read_decays

KVLCC2 = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
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
@pytest.mark.slow
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
@pytest.mark.slow
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


COMPONENT_KEYS = ["B_F", "B_W", "B_E", "B_L", "B_BK"]


@pytest.mark.skipif(not KVLCC2.is_file(), reason=f"the KVLCC2 roll decay is not at {KVLCC2}")
@pytest.mark.slow
def test_a_table_with_ikedas_components_explains_the_gap_as_tankdaqs_own_prediction_does(
    tmp_path: Path,
) -> None:
    """The KVLCC2 prediction written with its components beside B̂44 (as ``tankdaq predict --json`` rows
    are): the same lines of which component would have to change, and by how much, as ``ikeda``."""
    runs = cut_free_decays(read_decays(KVLCC2, "roll", "time", "phi", None, "rad"), None, None)
    hull = load_hull("kvlcc2")
    request = SimulationRequest(tuple(runs), "roll", hull, 1.0)
    prediction = ikeda_prediction(hull, 1.0, period_s=dominant_period_s(runs))
    rows = prediction.summary([math.radians(a) for a in (2, 4, 6, 8, 10, 12)])["amplitudes"]
    header = ["amplitude_deg", "B_44", *COMPONENT_KEYS]
    table = _table(tmp_path / "ikeda_sheet.csv", header, [[r[k] for k in header] for r in rows])
    from_table, own = resolve_simulation([str(table)], request), resolve_simulation(["ikeda"], request)
    assert from_table.component_changes is not None and own.component_changes is not None
    measured_b1, measured_b2 = 0.5 * own.coefficients["b1"], 0.7 * own.coefficients["b2"]
    amplitudes = request.amplitudes_rad()
    # its components are corrections of their own, as the prediction's: each the same part of b1 or b2
    assert from_table.shares is not None and own.shares is not None
    assert set(from_table.shares) == set(own.shares) == {"B_F", "B_W", "B_E"}
    for key, (term, value) in own.shares.items():
        assert from_table.shares[key][0] == term and from_table.shares[key][1] == pytest.approx(
            value, rel=1e-4
        )
    assert from_table.component_changes(measured_b1, measured_b2, amplitudes) == own.component_changes(
        measured_b1, measured_b2, amplitudes
    )
    # the components alone, no total: their sum is the B̂44
    alone = _table(
        tmp_path / "parts.csv",
        ["amplitude_deg", *COMPONENT_KEYS],
        [[r[k] for k in ["amplitude_deg", *COMPONENT_KEYS]] for r in rows],
    )
    parts = resolve_simulation([str(alone)], request)
    for term in ("b1", "b2", "c1"):
        assert parts.coefficients[term] == pytest.approx(own.coefficients[term], rel=1e-6), term
    assert parts.component_changes is not None
    assert parts.component_changes(measured_b1, measured_b2, amplitudes) == own.component_changes(
        measured_b1, measured_b2, amplitudes
    )


def test_components_are_shares_of_the_damping_and_must_add_up_to_a_b44_hat(
    measured: Path, tmp_path: Path
) -> None:
    """Components in any unit beside ``b_eq_per_s`` are its shares; beside ``b44_hat`` they must add up to
    it, or they are left out with a line (a sheet whose columns slipped explains nothing)."""
    runs = cut_free_decays(read_decays(measured), None, None)
    omega = 2 * math.pi / dominant_period_s(runs)
    slope = 8 / (3 * math.pi) * omega
    # linear components 3 + 1 + 0 (friction, wave, lift), quadratic 2 * phi_a / 2deg (eddy, none of keel)
    amplitudes = [2.0, 4.0, 6.0]
    rows = [[a, 3.0, 1.0, 2.0 * a / 2.0, 0.0, 0.0] for a in amplitudes]
    total = [r[1] + r[2] + r[3] for r in rows]
    b_eq = [0.02 * t for t in total]  # 1/s: the table's totals, in another unit than its components
    shares = _table(
        tmp_path / "shares.csv",
        ["amplitude_deg", "b_eq_per_s", *COMPONENT_KEYS],
        [[r[0], b, *r[1:]] for r, b in zip(rows, b_eq, strict=True)],
    )
    simulation = resolve_simulation([str(shares)], SimulationRequest(tuple(runs)))
    linear_b1 = 0.02 * 4.0  # the linear components' share of B_eq / I: amplitude-free
    quadratic_b2 = 0.02 * 2.0 / math.radians(2.0) / slope  # the eddy's: proportional to the amplitude
    assert simulation.coefficients["b1"] == pytest.approx(linear_b1)
    assert simulation.coefficients["b2"] == pytest.approx(quadratic_b2)
    assert simulation.component_changes is not None
    linear, quadratic = simulation.component_changes(2 * linear_b1, quadratic_b2, [])
    assert linear.startswith("b1:") and "would have to change x2 " in linear  # the measured b1 is twice
    assert quadratic.startswith("b2:") and "would have to change x1 " in quadratic  # as predicted

    off = _table(
        tmp_path / "off.csv",
        ["amplitude_deg", "b44_hat", *COMPONENT_KEYS],
        [[r[0], 1.1 * t, *r[1:]] for r, t in zip(rows, total, strict=True)],  # 10 % more than its parts
    )
    simulation = resolve_simulation([str(off)], SimulationRequest(tuple(runs), hull=load_hull("swath")))
    assert simulation.component_changes is None
    assert any(
        "components (B_F, B_W, B_E, B_L, B_BK) not used" in n and "off by up to 9%" in n
        for n in simulation.notes
    )
