"""``tankdaq campaign --executor dask`` on a real cluster: a ``dask scheduler`` and two ``dask worker``
processes started (and stopped) here, 24 short decays, the pool's results to 1e-12."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from typer.testing import CliRunner

from support.campaign_scale import dask_cluster, write_many_decays
from tankdaq.campaign.executors import CLIENT_BATCH_S, DaskExecutor, campaign_executor
from tankdaq.campaign.groups import find_campaign_hulls, find_recordings
from tankdaq.campaign.stream import completed, fit_campaign, scan_campaign, scan_file
from tankdaq.campaign.synthetic import SimulatedTest
from tankdaq.cli import app

pytest.importorskip("distributed", reason="the dask extra is not installed (pip install 'tankdaq[dask]')")

N_DECAYS = 24  # 12 groups, six for each worker: every group's fit crosses the cluster; bench_campaign_scale
# runs the thousands (the claim, the pool's results to 1e-12, does not depend on the count)
SHORT = SimulatedTest(duration_s=3.0)  # three pitch periods: enough to fit, cheap to read


@pytest.mark.slow
@pytest.mark.filterwarnings("error:Sending large graph")  # each group's fit goes to the cluster once
def test_a_dask_cluster_of_two_workers_gives_the_pools_results(tmp_path: Path) -> None:
    folder = tmp_path / "decays"
    write_many_decays(folder, N_DECAYS, hulls=("trimaran",), drafts=(1.0,), test=SHORT)
    with campaign_executor(jobs=2) as pool:
        scan = scan_campaign(find_recordings([folder]), executor=pool)
        groups = scan.groups()
        hulls = find_campaign_hulls({key.hull for key in groups})  # as the command: dimensional columns
        rows = sorted(fit_campaign(groups, hulls=hulls, executor=pool), key=lambda row: row.key)
    report = tmp_path / "report"
    with dask_cluster(2, tmp_path) as (address, processes):
        command = [
            "campaign",
            str(folder),
            "--executor",
            "dask",
            "--scheduler",
            address,
            "--report",
            str(report),
        ]
        result = CliRunner().invoke(app, command)
        a_pass_stopped_early_leaves_nothing_on_the_cluster(address, find_recordings([folder])[:8])
    assert all(process.poll() is not None for process in processes)  # every process started is stopped
    assert result.exit_code == 0, result.output
    with (report / "campaign.csv").open() as fh:
        on_dask = list(csv.DictReader(fh))
    assert len(rows) == N_DECAYS // 2 and sum(row.row["runs"] for row in rows) == N_DECAYS
    assert len(on_dask) == len(rows)
    for mine, expected in zip(on_dask, (row.row for row in rows), strict=True):
        assert mine["error"] == expected["error"] == "" and mine.keys() >= expected.keys()
        # campaign.csv's columns are every group's terms (the data choose each group's model): another
        # group's terms are empty in this row
        assert all(mine[column] == "" for column in mine.keys() - expected.keys())
        for column, value in expected.items():
            if isinstance(value, float):
                assert float(mine[column]) == pytest.approx(value, rel=1e-12, abs=1e-12), column
            else:
                assert mine[column] == str(value), column


def a_pass_stopped_early_leaves_nothing_on_the_cluster(address: str, paths: list[Path]) -> None:
    """A pass goes out in one message through a client that batches for at most ``CLIENT_BATCH_S``; a
    consumer that stops after the first result cancels the rest (the client then holds no task)."""
    with campaign_executor(scheduler=address) as executor:
        assert isinstance(executor, DaskExecutor)
        client = executor._client
        assert client.scheduler_comm.interval <= CLIENT_BATCH_S
        passed = completed(executor, scan_file, [(path,) for path in paths])
        index, first = next(passed)
        assert first.path == paths[index]
        assert len(client.futures) == len(paths)
        passed.close()
        assert not client.futures
