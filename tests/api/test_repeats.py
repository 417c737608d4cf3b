"""One decay in two files whose bytes differ (a CSV re-saved by a spreadsheet: other decimals, separator,
unit and column names) is one decay: ``identify`` fits it once and says so, a campaign's group that holds
it twice is doubted; two real decays of one condition are never taken for one."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import tankdaq
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.ident.free_decay import cut_free_decays
from tankdaq.ident.inputs import read_decays
from tankdaq.ident.plausibility import check_repeats

KVLCC2 = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)


def _resaved(
    source: Path, target: Path, time_col: str, angle_col: str, scale: float = 1.0, name: str = ""
) -> Path:
    """``source`` as a European spreadsheet saves it: semicolons, decimal commas, five significant digits;
    the angle times ``scale`` under ``name`` (another unit) where given, else as it was."""
    table = pd.read_csv(source)
    with target.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f, delimiter=";")
        writer.writerow([time_col, name or angle_col])
        for t, angle in zip(table[time_col], table[angle_col] * scale, strict=True):
            writer.writerow([f"{t:.5g}".replace(".", ","), f"{angle:.5g}".replace(".", ",")])
    return target


@pytest.fixture(scope="module")
def lab_csvs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two swath decays at T and 8 deg (seeded apart), as a lab's CSVs."""
    folder = tmp_path_factory.mktemp("lab")
    first = write_simulated_campaign(folder / "a", ["swath"], "roll", [1.0], [8.0], "csv", seed=1)
    second = write_simulated_campaign(folder / "b", ["swath"], "roll", [1.0], [8.0], "csv", seed=2)
    return [*first, *second]


def test_a_decay_resaved_by_a_spreadsheet_is_fitted_once_and_said(
    lab_csvs: list[Path], tmp_path: Path
) -> None:
    original = lab_csvs[0]
    copy = _resaved(original, tmp_path / "21337 (Excel).csv", "time_s", "angle_deg")
    alone = tankdaq.identify(original, "b1,b3,c1,c3", reading=tankdaq.Reading(rate_col=None))
    both = tankdaq.identify([original, copy], "b1,b3,c1,c3", reading=tankdaq.Reading(rate_col=None))
    said = [line for line in both.notices if line.startswith("not used: ")]
    assert len(said) == 1 and "is the same decay as" in said[0] and copy.name in said[0], both.notices
    pd.testing.assert_frame_equal(both.coefficients, alone.coefficients)


def test_two_real_decays_of_one_condition_are_two(lab_csvs: list[Path]) -> None:
    runs = [run for path in lab_csvs for run in cut_free_decays(read_decays(path), None, None)]
    assert len(runs) == 2 and runs[0].t.size == runs[1].t.size  # alike in all but their noise
    assert check_repeats(runs) == []
    found = tankdaq.identify(lab_csvs, "b1,b3,c1,c3")
    assert not any(line.startswith("not used: ") for line in found.notices)
    assert len(found.fits[0].runs) == 2


def _rows(source: Path, target: Path, start: float, stop: float) -> Path:
    """A colleague's copy of ``source``: only the rows from fraction ``start`` to ``stop`` of it, with the
    time column as it was (re-saved by pandas: other decimals)."""
    table = pd.read_csv(source)
    table.iloc[round(start * len(table)) : round(stop * len(table))].to_csv(
        target, index=False, float_format="%.6g"
    )
    return target


def _free_decays(*paths: Path) -> list:
    return [run for path in paths for run in cut_free_decays(read_decays(path, rate_col=None), None, None)]


@pytest.mark.parametrize(
    ("start", "stop"),
    [(0.0, 0.6), (0.0, 0.9), (0.45, 1.0), (0.3, 0.8)],
    ids=["first-60%", "first-90%", "from-the-middle", "a-middle-half"],
)
@pytest.mark.slow
def test_a_copy_cut_at_another_point_is_the_same_decay(
    lab_csvs: list[Path], tmp_path: Path, start: float, stop: float
) -> None:
    original = lab_csvs[0]
    cut = _rows(original, tmp_path / "21337 selected.csv", start, stop)
    runs = _free_decays(original, cut)
    assert runs[0].t.size != runs[1].t.size  # their sample counts differ: not the same file re-saved
    (finding,) = check_repeats(runs)
    assert "a cut of the same decay" in finding.message and cut.name in finding.message, finding.message
    alone = tankdaq.identify(original, "b1,b3,c1,c3", reading=tankdaq.Reading(rate_col=None))
    both = tankdaq.identify([cut, original], "b1,b3,c1,c3", reading=tankdaq.Reading(rate_col=None))
    said = [line for line in both.notices if line.startswith("not used: ")]
    assert len(said) == 1 and said[0].startswith(f"not used: {runs[1].name}"), (
        both.notices
    )  # the longer stays
    pd.testing.assert_frame_equal(both.coefficients, alone.coefficients)


def test_two_real_decays_cut_alike_or_apart_stay_two(lab_csvs: list[Path], tmp_path: Path) -> None:
    """Parts of two real decays of one condition share no stretch, however they are cut."""
    first = _rows(lab_csvs[0], tmp_path / "a.csv", 0.0, 0.6)
    second = _rows(lab_csvs[1], tmp_path / "b.csv", 0.2, 1.0)
    assert check_repeats(_free_decays(first, lab_csvs[1])) == []
    assert check_repeats(_free_decays(lab_csvs[0], second)) == []
    assert check_repeats(_free_decays(first, second)) == []


def test_a_group_holding_one_decay_twice_is_doubted(lab_csvs: list[Path], tmp_path: Path) -> None:
    original = lab_csvs[0]
    copy = _resaved(original, tmp_path / "copy.csv", "time_s", "angle_deg", np.pi / 180, "angle_rad")
    runs = cut_free_decays(read_decays(original, rate_col=None), None, None)
    runs += cut_free_decays(read_decays(copy, angle_col="angle_rad", rate_col=None), None, None)
    (finding,) = check_repeats(runs)
    assert finding.about_data and "is the same decay as" in finding.message


@pytest.mark.skipif(not KVLCC2.is_file(), reason=f"the KVLCC2 roll decay is not at {KVLCC2}")
@pytest.mark.slow
def test_the_kvlcc2_run_resaved_in_degrees_is_the_same_decay(tmp_path: Path) -> None:
    copy = _resaved(KVLCC2, tmp_path / "21338_deg.csv", "time", "phi", 180 / np.pi, "phi_deg")
    runs = cut_free_decays(read_decays(KVLCC2, "roll", "time", "phi", None, "rad"), None, None)
    runs += cut_free_decays(read_decays(copy, "roll", "time", "phi_deg", None), None, None)
    assert [f.check for f in check_repeats(runs)] == ["repeated"]
    trimmed = _rows(KVLCC2, tmp_path / "21338_first_cycles.csv", 0.0, 0.5)
    runs[1:] = cut_free_decays(read_decays(trimmed, "roll", "time", "phi", None, "rad"), None, None)
    (finding,) = check_repeats(runs)
    assert "a cut of the same decay" in finding.message
