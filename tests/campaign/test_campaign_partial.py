"""A folder campaign fits only decays recorded whole: one stopped 3 s after its release is left out with
a line saying how it ended, unless asked for (issue 37, item 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import tankdaq
from tankdaq.campaign.synthetic import (
    SimulatedTest,
    simulated_decay,
    write_simulated_campaign,
    write_simulated_recording,
)
from tankdaq.cli import app
from tankdaq.config.hulls import load_hull
from tankdaq.errors import InputError


def _stopped(folder: Path, angle_deg: float, extra: dict[str, object]) -> Path:
    """A swath roll decay at T held 0.5 s and stopped 3 s after its release."""
    test = SimulatedTest(duration_s=3.5)
    coefficients = load_hull("swath").simulation_model("roll").coefficients(1.0)
    t, angle, rate = simulated_decay(coefficients, angle_deg, test, np.random.default_rng(5))
    name = f"swath_T_roll_{angle_deg:g}deg_stopped.mcap"
    return write_simulated_recording(
        folder / name, ("swath", "roll", 1.0, angle_deg), t, angle, rate, test, extra
    )


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    made = tmp_path_factory.mktemp("partial")
    write_simulated_campaign(made, ["swath"], "roll", [1.0], [6.0], "mcap")
    _stopped(made, 7.0, {"ended": "stopped"})
    _stopped(made, 9.0, {"settle_reason": "note"})  # a file from before DecayEnd: stopped too
    return made


def _angles(result: tankdaq.api.campaigns.Campaign) -> set[float]:
    return {round(float(row.row["angle_deg"])) for row in result.rows}


def test_a_stopped_decay_is_left_out_of_a_folder_campaign_with_its_line(folder: Path) -> None:
    result = tankdaq.campaign(folder, "b1,c1")
    assert _angles(result) == {6}
    left_out = [line for line in result.notices if "left out (--include-partial fits it)" in line]
    assert len(left_out) == 2, result.notices
    assert any("stopped by the operator" in line and "after the release" in line for line in left_out)


def test_include_partial_fits_them_as_asked(folder: Path) -> None:
    result = tankdaq.campaign(folder, "b1,c1", include_partial=True)
    assert _angles(result) == {6, 7, 9}
    assert sum("fitted as asked" in line for line in result.notices) == 2


@pytest.mark.slow
def test_a_folder_of_partial_decays_only_is_one_line(tmp_path: Path) -> None:
    _stopped(tmp_path, 7.0, {"ended": "device_lost"})
    with pytest.raises(InputError, match=r"recorded only in part.*--include-partial"):
        tankdaq.campaign(tmp_path, "b1,c1")
    done = CliRunner().invoke(app, ["campaign", str(tmp_path), "--model", "b1,c1", "--jobs", "1"])
    assert done.exit_code == 2 and "Traceback" not in done.output
    assert "recorded only in part" in done.output
