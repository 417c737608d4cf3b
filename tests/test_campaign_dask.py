"""``tankdaq campaign --executor dask`` on a real cluster: a ``dask scheduler`` and two ``dask worker``
processes started (and stopped) here, 360 short decays, the pool's results to 1e-12."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from typer.testing import CliRunner

from campaign_scale import dask_cluster, write_many_decays
from tankdaq.cli import app
from tankdaq.ident.campaign import SimulatedTest

pytest.importorskip("distributed", reason="the dask extra is not installed (pip install 'tankdaq[dask]')")

N_DECAYS = 360
SHORT = SimulatedTest(duration_s=3.0)  # three pitch periods: enough to fit, cheap to read


def campaign_table(folder: Path, report: Path, *options: str) -> list[dict[str, str]]:
    result = CliRunner().invoke(app, ["campaign", str(folder), "--report", str(report), *options])
    assert result.exit_code == 0, result.output
    with (report / "campaign.csv").open() as fh:
        return list(csv.DictReader(fh))


def test_a_dask_cluster_of_two_workers_gives_the_pools_results(tmp_path: Path) -> None:
    folder = tmp_path / "decays"
    write_many_decays(folder, N_DECAYS, hulls=("trimaran",), drafts=(1.0,), test=SHORT)
    pool = campaign_table(folder, tmp_path / "pool", "--jobs", "2")
    with dask_cluster(2, tmp_path) as (address, processes):
        on_dask = campaign_table(folder, tmp_path / "dask", "--executor", "dask", "--scheduler", address)
    assert all(process.poll() is not None for process in processes)  # every process started is stopped
    assert len(pool) == N_DECAYS // 2 and sum(int(row["runs"]) for row in pool) == N_DECAYS
    assert [row.keys() for row in on_dask] == [row.keys() for row in pool]
    for mine, theirs in zip(on_dask, pool, strict=True):
        assert mine["error"] == theirs["error"] == ""
        for column, value in theirs.items():
            try:
                expected = float(value)
            except ValueError:
                assert mine[column] == value, column
            else:
                assert float(mine[column]) == pytest.approx(expected, rel=1e-12, abs=1e-12), column
