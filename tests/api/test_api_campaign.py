"""``tankdaq campaign`` is ``tankdaq.campaign`` (issue 23 item 1, issue 22 item 3): one streamed pipeline.

Real recordings written by ``tankdaq.simulate``, the command run in-process on the same folder: the
command's ``--json`` and the call's table must hold the same numbers.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

import tankdaq
from tankdaq.cli import app
from tankdaq.errors import InputError

runner = CliRunner()


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two conditions of two decays each: two groups."""
    root = tmp_path_factory.mktemp("campaign")
    tankdaq.simulate(root, seed=3, runs=2, decay_s=12.0)
    tankdaq.simulate(root, draft="1.1T", seed=4, runs=2, decay_s=12.0)
    return root


def same(a: object, b: object) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-15)
    return a == b


@pytest.mark.slow
def test_the_command_json_and_the_call_give_the_same_numbers(folder: Path) -> None:
    done = runner.invoke(app, ["campaign", str(folder), "--model", "b1,b2,c1", "--jobs", "1", "--json"])
    assert done.exit_code == 0, done.output
    document = json.loads(done.stdout)
    result = tankdaq.campaign(folder, "b1,b2,c1")
    rows = result.table.to_dict("records")
    assert [row["draft"] for row in rows] == ["T", "1.1T"] and [row["runs"] for row in rows] == [2, 2]
    assert len(document["groups"]) == len(rows)
    for given, row in zip(document["groups"], rows, strict=True):
        assert set(given) == set(row)
        numbers = [key for key, value in row.items() if isinstance(value, float)]
        assert {"b1", "b2", "c1", "b1_std", "natural_period_s", "b_eq_per_s", "r2_angle"} <= set(numbers)
        for key in numbers:
            assert same(float("nan") if given[key] is None else given[key], row[key]), key
    assert document["warnings"] == result.warnings and document["skipped"] == []
    assert document["cuts"] == result.cuts and len(result.cuts) == 4
    assert f"read 4 recording(s) from 1 folder(s): {folder}" in done.stderr


@pytest.mark.slow
def test_each_fit_is_handed_over_as_it_arrives_and_kept_only_when_asked(folder: Path) -> None:
    handed: list = []
    light = tankdaq.campaign(folder, "b1,b2,c1", on_result=handed.append)
    assert sorted(fit.key.label for fit in handed) == sorted(row.key.label for row in light.rows)
    assert all(fit.fit is not None and len(fit.runs) == 2 for fit in handed)
    assert light.results == [] and all(row.result is None for row in light.rows)
    kept = tankdaq.campaign(folder, "b1,b2,c1", keep_fits=True)
    assert [r.key for r in kept.results] == [row.key for row in light.rows]
    assert [r.summary()["b1"] for r in kept.results] == list(light.table["b1"])


def test_bad_settings_are_one_line_before_any_file_is_read(tmp_path: Path) -> None:
    cases = [
        ({"executor": "spark"}, "executor 'spark' not understood"),
        ({"executor": "dask"}, "executor dask needs scheduler"),
        ({"jobs": 0}, "jobs: give a whole number from 1"),
        ({"model": "b9"}, "b9"),
    ]
    for settings, said in cases:
        with pytest.raises(InputError) as caught:
            tankdaq.campaign(tmp_path / "nothing-here", **settings)
        assert said in str(caught.value) and "\n" not in str(caught.value)
