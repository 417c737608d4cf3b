"""The commands that used to work inside the CLI are API calls (issue 23 item 1): ``identify --compare`` is
``tankdaq.compare_models``, ``diagnose --simulation`` is ``tankdaq.diagnose(simulation=...)``; and the fits
they make reach the run catalogue: ``identify --joint`` and ``diagnose --simulation`` write their rows too.

Real recordings written by ``tankdaq.simulate``, a real SQLite catalogue, the commands run in-process.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import sqlalchemy as sa
from typer.testing import CliRunner

import tankdaq
from tankdaq.catalogue.database import open_catalogue
from tankdaq.catalogue.schema import decays
from tankdaq.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def two_drafts(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """One swath roll decay at T and one at 1.1T: two conditions."""
    folder = tmp_path_factory.mktemp("drafts")
    (design,) = tankdaq.simulate(folder, seed=7, decay_s=12.0)
    (deeper,) = tankdaq.simulate(folder, draft="1.1T", seed=8, decay_s=12.0)
    return [design.path, deeper.path]


def rows_of(url: str) -> dict[str, dict]:
    with open_catalogue(url) as catalogue, catalogue.engine.connect() as connection:
        return {Path(r.path).name: dict(r._mapping) for r in connection.execute(sa.select(decays))}


def timeless(document: dict) -> dict:
    """Without the wall times, the one value two runs never share."""
    return json.loads(json.dumps(document), object_hook=_drop_elapsed)


def _drop_elapsed(part: dict) -> dict:
    part.pop("elapsed_s", None)
    return part


@pytest.mark.slow
def test_identify_joint_writes_each_condition_s_rows(two_drafts: list[Path], tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    args = ["identify", *map(str, two_drafts), "--model", "b1,b2,c1", "--joint", "--catalogue", url, "--json"]
    done = runner.invoke(app, args)
    assert done.exit_code == 0, done.output
    document = json.loads(done.stdout)
    rows = rows_of(url)
    assert sorted(rows) == sorted(path.name for path in two_drafts)
    for path in two_drafts:
        row = rows[path.name]
        assert row["fit_source"] == "identify-joint"
        assert {t: v["value"] for t, v in row["coefficients"].items()} == {
            t: v["value"] for t, v in document["coefficients"].items()
        }
        assert row["warnings"][0] == document["warnings"][0] and "pooled" in row["warnings"][0]
    assert {rows[p.name]["draft"] for p in two_drafts} == {"T", "1.1T"}


@pytest.mark.slow
def test_diagnose_simulation_is_the_api_and_writes_the_measured_fit(
    two_drafts: list[Path], tmp_path: Path
) -> None:
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    measured = two_drafts[0]
    args = ["diagnose", str(measured), "--simulation", "hull", "--hull", "swath", "--max-steps", "1"]
    done = runner.invoke(app, [*args, "--catalogue", url, "--json"])
    assert done.exit_code == 0, done.output
    command = json.loads(done.stdout)
    assert command.pop("truncated") is False and command.pop("truncated_files") == []
    found = tankdaq.diagnose(measured, simulation="hull", hull="swath", max_steps=1)
    assert found.comparison is not None and found.diagnoser is None
    assert timeless(found.document) == timeless(command)
    (row,) = rows_of(url).values()
    assert row["fit_source"] == "diagnose"
    assert {t: v["value"] for t, v in row["coefficients"].items()} == found.estimator.coefficients_


@pytest.mark.slow
def test_identify_compare_is_compare_models(two_drafts: list[Path]) -> None:
    done = runner.invoke(app, ["identify", str(two_drafts[0]), "--compare", "--json"])
    assert done.exit_code == 0, done.output
    command = json.loads(done.stdout)
    found = tankdaq.compare_models(two_drafts[0])
    assert timeless(json.loads(found.to_json())) == timeless(command)
    assert list(found.table["bic"]) == [row["bic"] for row in command["compare"]]
    assert [row["models"] for row in found.rows] == [row["models"] for row in command["compare"]]
    assert command["warnings"] == [] and len(command["cuts"]) == 1


@pytest.mark.parametrize("command", ["identify", "diagnose", "simulate", "simulate-campaign"])
@pytest.mark.slow
def test_every_axis_option_is_checked_alike_while_parsing(command: str, tmp_path: Path) -> None:
    """``--axis`` is defined once (``cli.options``): the same one line and exit 2 everywhere, before any
    file is read or written."""
    given = {"identify": [str(tmp_path)], "diagnose": [str(tmp_path)], "simulate-campaign": [str(tmp_path)]}
    done = runner.invoke(app, [command, *given.get(command, []), "--axis", "yaw"])
    assert done.exit_code == 2, done.output
    assert done.stderr.strip() == "error: --axis 'yaw' not understood: use roll or pitch"
    assert list(tmp_path.iterdir()) == []
