"""``tankdaq simulate`` as people run it: a subprocess whose first stdout line is a port."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tankdaq.device.driver import MTiDriver

TANKDAQ = [str(Path(sys.executable).with_name("tankdaq"))]  # the installed console script


def _start(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*TANKDAQ, "simulate", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


@pytest.mark.slow
def test_simulate_prints_a_port_a_driver_can_open_and_stops_cleanly(tmp_path: Path) -> None:
    truth_path = tmp_path / "truth.json"
    process = _start("--speed", "5", "--runs", "2", "--seed", "3", "--truth", str(truth_path))
    try:
        port = process.stdout.readline().strip()  # type: ignore[union-attr]
        assert os.path.exists(port)
        with MTiDriver(port) as driver:
            info = driver.configure()
            samples = driver.samples(1.0)
        assert info.product_code.startswith("MTi-G")
        assert samples.size == 100
    finally:
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=10)
    assert process.returncode == 0, err
    assert not os.path.exists(port)  # the simulator cleaned up its link
    truth = json.loads(truth_path.read_text())
    assert truth["hull"] == "swath" and truth["axis"] == "roll" and truth["draft"] == "T"
    assert len(truth["runs"]) == 2
    run = truth["runs"][0]
    assert run["kind"] == "release"
    assert 10.0 <= run["release_s"] <= 10.01
    assert run["release_ticks"] == (truth["start_ticks"] + round(run["release_s"] * 10_000)) % 864_000_000
    assert set(run["coefficients"]) == {"b1", "b2", "b3", "c1", "c2", "c3"}
    assert abs(run["angle0_deg"]) == pytest.approx(8.0, abs=1.5)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--draft", "3T"], "outside 0.3T..2.0T"),
        (["--axis", "yaw"], "axis 'yaw'"),
        (["--rate", "120"], "not an MTi output rate"),
        (["--hull", "nope"], "unknown hull"),
        (["--faults", "melt=1"], "fault 'melt=1'"),
        (["--speed", "0"], "--speed must be positive"),
    ],
)
@pytest.mark.slow
def test_bad_values_exit_2_with_one_line(args: list[str], message: str) -> None:
    process = _start(*args)
    out, err = process.communicate(timeout=30)
    assert process.returncode == 2
    assert message in err
    assert "Traceback" not in err
    assert out == ""


@pytest.mark.slow
def test_simulate_sway_plays_the_swaying_hold(tmp_path: Path) -> None:
    """``--sway``: the truth is the swaying hold's (``Handling.swaying()``), not the still one's."""
    from tankdaq.config.hulls import hull_scenario
    from tankdaq.physics.scenario import Handling

    truth_path = tmp_path / "truth.json"
    process = _start("--sway", "--runs", "2", "--seed", "3", "--truth", str(truth_path))
    try:
        assert os.path.exists(process.stdout.readline().strip())  # type: ignore[union-attr]
    finally:
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=10)
    assert process.returncode == 0, err
    rates = [run["rate0_rad_s"] for run in json.loads(truth_path.read_text())["runs"]]
    holds = (Handling.swaying(), Handling())
    swaying, still = (hull_scenario(runs=2, seed=3, handling=hold).trace().runs for hold in holds)
    assert rates == [run.rate0_rad_s for run in swaying] != [run.rate0_rad_s for run in still]
