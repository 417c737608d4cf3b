"""Fresh decays: the simulator draws a new seed each run unless ``--seed`` is given, and says it (the
recording's metadata, ``--truth``), so two simulated tests never hold the same decay and a seed plays its
test again."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

import tankdaq
from tankdaq.cli import app
from tankdaq.store.schemas import RUN_METADATA_NAME

#: What the sensor measured (the host clock, the time a file was written, differs between any two runs).
MEASURED = ["ticks", "counter", "roll_deg", "pitch_deg", "p_deg_s", "q_deg_s", "az_m_s2"]
TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))  # the installed console script


def _seed_in(path: Path) -> int:
    """The ``sim_seed`` of a recording's run metadata, read back with the official MCAP reader."""
    with path.open("rb") as f:
        records = [m for m in make_reader(f).iter_metadata() if m.name == RUN_METADATA_NAME]
    return int(records[-1].metadata["sim_seed"])  # the closing record repeats the opening one


@pytest.fixture(scope="module")
def two_sim_records(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], str]:
    """``tankdaq record --port sim --runs 1`` twice into one folder, as the README has it (no --seed)."""
    out = tmp_path_factory.mktemp("recordings")
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8", "--runs", "1"]
    args += ["--out", str(out), "--viewer", "none", "--sim-speed", "20"]
    said = ""
    for _ in range(2):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        said += result.output
    return sorted(out.glob("*.mcap")), said


@pytest.mark.slow
def test_two_sim_records_hold_different_decays_and_each_names_its_seed(two_sim_records) -> None:
    paths, said = two_sim_records
    assert len(paths) == 2
    seeds = [_seed_in(path) for path in paths]
    assert seeds[0] != seeds[1]
    for seed in seeds:
        assert f"seed {seed}" in said  # the device line says it as the run starts
    result = CliRunner().invoke(app, ["identify", *map(str, paths), "--model", "b1,b2,c1,c3"])
    assert result.exit_code == 0, result.output
    assert "one decay from two files" not in result.output and "not used:" not in result.output


@pytest.mark.slow
def test_the_seed_a_file_names_plays_its_test_again(tmp_path: Path) -> None:
    """``tankdaq.simulate`` without a seed: each call its own decay, its seed in the file; that seed given
    back plays the same samples."""
    first, second = (tankdaq.simulate(tmp_path / name, decay_s=6.0)[0] for name in ("a", "b"))
    seed = _seed_in(first.path)
    assert seed != _seed_in(second.path)
    assert not np.array_equal(first.samples[MEASURED], second.samples[MEASURED])
    (again,) = tankdaq.simulate(tmp_path / "c", decay_s=6.0, seed=seed)
    assert _seed_in(again.path) == seed
    np.testing.assert_array_equal(again.samples[MEASURED], first.samples[MEASURED])


@pytest.mark.slow
def test_simulate_says_its_fresh_seed_in_the_truth_file(tmp_path: Path) -> None:
    """``tankdaq simulate --truth``: two runs without --seed name two seeds, on stderr and in the file."""
    seeds = []
    for name in ("one.json", "two.json"):
        truth = tmp_path / name
        process = subprocess.Popen(
            [TANKDAQ, "simulate", "--runs", "1", "--truth", str(truth)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            assert process.stdout is not None and process.stdout.readline().strip()  # serving: truth written
        finally:
            process.send_signal(signal.SIGTERM)
            _, err = process.communicate(timeout=10)
        assert process.returncode == 0, err
        seeds.append(json.loads(truth.read_text())["seed"])
        assert f"seed {seeds[-1]}" in err
    assert seeds[0] != seeds[1]
