"""Campaigns: simulated from the hull configs, written as real CSV and MCAP files, grouped and identified."""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread
from typer.testing import CliRunner

from tankdaq.campaign.executors import LocalPool, campaign_executor
from tankdaq.campaign.groups import (
    GroupKey,
    GroupResult,
    csv_labels,
    find_recordings,
    group_runs,
    identify_groups,
    markdown_table,
    read_campaign,
    read_campaign_runs,
)
from tankdaq.campaign.stream import (
    CHUNKS,
    MAX_CHUNK_DECAYS,
    RunRef,
    chunk_size,
    fit_campaign,
    fit_chunks,
    scan_campaign,
    scan_chunks,
)
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.cli import app
from tankdaq.config.hulls import load_hull
from tankdaq.errors import InputError
from tankdaq.ident.derived import b_eq
from tankdaq.records import DecayRun
from tankdaq.viz.campaign_report import load_plotting, write_report

HULLS = ("trimaran", "catamaran")
DRAFTS = (0.9, 1.1)
ANGLES_DEG = (4.0, 8.0)
runner = CliRunner()


def truth(key: GroupKey) -> dict[str, float]:
    return load_hull(key.hull).simulation_model(key.axis).coefficients(key.draft)


@pytest.fixture(scope="module")
def csv_campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("csv_campaign")
    write_simulated_campaign(folder, HULLS, "pitch", DRAFTS, ANGLES_DEG, "csv", seed=1)
    return folder


@pytest.fixture(scope="module")
def csv_results(csv_campaign: Path) -> list:
    runs = [run for path in find_recordings([csv_campaign]) for run in read_campaign_runs(path)]
    return identify_groups(group_runs(runs))


@pytest.mark.slow
def test_every_condition_is_one_group_and_recovers_its_hull(csv_results: list) -> None:
    keys = [r.key for r in csv_results]
    expected = {GroupKey(h, "pitch", d, a) for h in HULLS for d in DRAFTS for a in ANGLES_DEG}
    assert set(keys) == expected and len(keys) == len(expected)
    for result in csv_results:
        true = truth(result.key)
        fitted = result.fit.coefficients_
        assert fitted["c1"] == pytest.approx(true["c1"], rel=0.005), result.key
        assert fitted["b1"] == pytest.approx(true["b1"], rel=0.05), result.key
        amplitude = math.radians(result.key.angle_deg)
        assert b_eq(fitted, amplitude) == pytest.approx(b_eq(true, amplitude), rel=0.03), result.key


@pytest.mark.slow
def test_report_files_hold_the_table_and_the_plots(csv_results: list, tmp_path: Path) -> None:
    written = write_report(csv_results, tmp_path)
    names = {p.name for p in written}
    assert {"campaign.csv", "campaign.md", "hulls_pitch_0.9T.png", "period_vs_draft_pitch.png"} <= names
    for hull in HULLS:
        assert {
            f"coefficients_{hull}_pitch.png",
            f"b_eq_{hull}_pitch.png",
            f"extinction_{hull}_pitch.png",
        } <= names
    with (tmp_path / "campaign.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(csv_results)
    for row, result in zip(rows, csv_results, strict=True):
        assert float(row["c1"]) == pytest.approx(result.fit.coefficients_["c1"], rel=1e-9)
        assert row["draft"] in ("0.9T", "1.1T") and row["error"] == ""
    table = (tmp_path / "campaign.md").read_text()
    assert table.count("| trimaran | pitch |") == len(DRAFTS) * len(ANGLES_DEG)
    for png in (p for p in written if p.suffix == ".png"):
        image = imread(png)
        assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100
        assert float(np.std(image)) > 0.01, png.name  # something was drawn


def assert_same_fits(results: list[GroupResult], expected: list[GroupResult]) -> None:
    """Bit-identical fits: the same groups in the same order, same parameters and covariance."""
    assert [r.key for r in results] == [r.key for r in expected]
    for result, serial in zip(results, expected, strict=True):
        assert result.error == serial.error
        np.testing.assert_array_equal(result.fit.params_, serial.fit.params_)
        np.testing.assert_array_equal(result.fit.param_covariance_, serial.fit.param_covariance_)


@pytest.mark.slow
def test_a_process_pool_gives_the_serial_results(
    csv_campaign: Path, csv_results: list, tmp_path: Path
) -> None:
    """Reading, fits and plots spread over worker processes; tables and figures as from one process."""
    serial_files = write_report(csv_results, tmp_path / "serial")
    paths = find_recordings([csv_campaign])
    with campaign_executor(jobs=2, prepare=[load_plotting]) as pool:
        assert pool is not None
        runs = [run for found in pool.map(read_campaign_runs, paths) for run in found]
        results = identify_groups(group_runs(runs), executor=pool)
        pool_files = write_report(results, tmp_path / "pool", pool)
    assert_same_fits(results, csv_results)
    assert [p.name for p in pool_files] == [p.name for p in serial_files]
    for mine, serial in zip(pool_files, serial_files, strict=True):
        if mine.suffix == ".png":
            np.testing.assert_array_equal(imread(mine), imread(serial), err_msg=mine.name)
        else:
            assert mine.read_text() == serial.read_text()


@pytest.mark.slow
def test_a_dask_cluster_gives_the_serial_results(csv_campaign: Path, csv_results: list) -> None:
    """``--executor dask``: the same units of work on a (here local, in-process) Dask cluster."""
    distributed = pytest.importorskip(
        "distributed", reason="the dask extra is not installed (pip install 'tankdaq[dask]')"
    )
    runs = [run for path in find_recordings([csv_campaign]) for run in read_campaign_runs(path)]
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
        ) as cluster,
        campaign_executor(scheduler=cluster.scheduler_address) as executor,
    ):
        results = identify_groups(group_runs(runs), executor=executor)
        groups = scan_campaign(find_recordings([csv_campaign]), executor=executor).groups()
        chunks = list(fit_chunks(list(groups.items()), executor))
        rows = sorted(fit_campaign(groups, executor=executor), key=lambda row: row.key)
    assert_same_fits(results, csv_results)
    assert [row.row for row in rows] == [result.summary() for result in csv_results]
    # the cluster's size is known, and the fits go in chunks of whole groups that shrink to one group
    assert executor.threads == 2
    assert [group for chunk in chunks for group in chunk] == list(groups.items())
    sizes = [sum(len(refs) for _, refs in chunk) for chunk in chunks]
    assert sizes == sorted(sizes, reverse=True) and sizes[0] > sizes[-1] and len(chunks[-1]) == 1


def test_a_local_pool_fits_in_chunks_of_one_size() -> None:
    """The pool's chunks (``CHUNKS``): equal until the last, whole groups, at most ``MAX_CHUNK_DECAYS``."""
    paths = [Path(f"r{i}.mcap") for i in range(400)]
    keys = [GroupKey("trimaran", "pitch", 1.0, float(i)) for i in range(200)]
    groups = [(key, [RunRef(p, 0) for p in paths[i::200]]) for i, key in enumerate(keys)]
    chunks = list(fit_chunks(groups, None))
    sizes = [sum(len(refs) for _, refs in chunk) for chunk in chunks]
    assert [group for chunk in chunks for group in chunk] == groups
    assert set(sizes[:-1]) == {2 * math.ceil(chunk_size(400) / 2)}  # whole groups of two: 13 -> 14
    assert chunk_size(400) == math.ceil(400 / CHUNKS) and chunk_size(10**6) == MAX_CHUNK_DECAYS


def test_the_scan_goes_to_each_worker_in_one_run_of_files_of_about_equal_bytes(tmp_path: Path) -> None:
    """A scan costs about its file's bytes and a task a pickle each way: one chunk per worker of a local
    pool (or a cluster's thread), neighbouring files of about equal bytes, none over
    ``MAX_CHUNK_DECAYS`` files; each file alone without a pool (progress after each)."""
    sizes = [40_000, *[1_000] * 30, 39_000, 1_000]  # a long recording at each end of the middle
    paths = []
    for i, size in enumerate(sizes):
        paths.append(tmp_path / f"r{i:02d}.mcap")
        paths[-1].write_bytes(b"x" * size)
    paths.append(tmp_path / "gone.mcap")  # vanished since it was found: its scan says so
    assert scan_chunks(paths, None) == [[path] for path in paths]
    with LocalPool(2) as pool:  # not started: a pool forks its workers at its first task
        assert pool.workers == 2
        chunks = scan_chunks(paths, pool)
        many = scan_chunks([tmp_path / f"{i}.mcap" for i in range(3 * MAX_CHUNK_DECAYS + 1)], pool)
    assert [path for chunk in chunks for path in chunk] == paths and len(chunks) == 2
    chunk_bytes = [sum(path.stat().st_size for path in chunk if path.exists()) for chunk in chunks]
    assert abs(chunk_bytes[0] - chunk_bytes[1]) <= max(sizes)  # equal but for the file at the cut
    assert len(many) == 4 and max(len(chunk) for chunk in many) <= MAX_CHUNK_DECAYS


@pytest.mark.parametrize("second", ["export beside", "export elsewhere", "copy"])
@pytest.mark.slow
def test_a_recording_read_twice_is_one_decay_not_two(tmp_path: Path, second: str) -> None:
    """A folder's recordings a second time (``tankdaq export`` writes its CSV beside each recording by
    default; or the recordings copied into a "selected" folder): a campaign or an identify pooled each
    decay twice, as two repeats: runs 2 and every interval narrowed by about 1/sqrt(2). The second
    file is left out, and said so."""
    folder = tmp_path / "recordings"
    write_simulated_campaign(folder, ["trimaran"], "pitch", [1.0], [6.0, 10.0], "mcap", seed=3)
    recordings = sorted(folder.glob("*.mcap"))
    out = folder if second == "export beside" else tmp_path / "second"
    if second == "copy":
        shutil.copytree(folder, out)
        seconds = sorted(out.glob("*.mcap"))
    else:
        exported = runner.invoke(app, ["export", *map(str, recordings), "--format", "csv", "--out", str(out)])
        assert exported.exit_code == 0, exported.output
        seconds = sorted(out.glob("*.csv"))
    assert len(seconds) == len(recordings) == 2
    both = [folder] if second == "export beside" else [folder, out]
    result = runner.invoke(app, ["campaign", *map(str, both), "--json", "--catalogue", "none"])
    assert result.exit_code == 0, result.output
    assert [group["runs"] for group in json.loads(result.stdout)["groups"]] == [1, 1]
    said = [line for line in result.stderr.splitlines() if line.startswith("not read: ")]
    why = "holds the same bytes as" if second == "copy" else "is the export of"
    assert len(said) == 2 and all(why in line for line in said), said
    pair = [str(recordings[0]), str(seconds[0])]
    single = runner.invoke(app, ["identify", *pair, "--json", "--catalogue", "none"])
    assert single.exit_code == 0, single.output
    assert len(json.loads(single.stdout)["runs"]) == 1


def test_mcap_campaign_reads_back_like_the_csv_one(tmp_path: Path) -> None:
    """Real tankdaq recordings (held tilt + release event) give the same groups and the hull's values."""
    write_simulated_campaign(tmp_path, ["trimaran"], "pitch", [1.0], [6.0], "mcap", seed=2)
    paths = find_recordings([tmp_path])
    assert [p.suffix for p in paths] == [".mcap"]
    runs = read_campaign_runs(paths[0])
    assert runs[0].t[0] == pytest.approx(0.5)  # cut at the release event, after the held tilt
    (result,) = identify_groups(group_runs(runs))
    assert result.key == GroupKey("trimaran", "pitch", 1.0, 6.0)
    assert result.fit.coefficients_["c1"] == pytest.approx(truth(result.key)["c1"], rel=0.005)


def test_repeats_are_fitted_jointly(csv_campaign: Path, tmp_path: Path) -> None:
    """Two files of the same condition (run01, run02) form one group with both runs."""
    source = csv_campaign / "trimaran_0.9T_pitch_8deg_run01.csv"
    shutil.copy(source, tmp_path / source.name)
    shutil.copy(source, tmp_path / "trimaran_0.9T_pitch_8deg_run02.csv")
    runs = [run for path in find_recordings([tmp_path]) for run in read_campaign_runs(path)]
    groups = group_runs(runs)
    assert list(groups) == [GroupKey("trimaran", "pitch", 0.9, 8.0)]
    (result,) = identify_groups(groups)
    assert len(result.runs) == 2 and result.summary()["runs"] == 2


def test_a_sidecar_names_the_condition(tmp_path: Path) -> None:
    path = tmp_path / "decay 17.csv"
    path.write_text("time_s,angle_deg\n")
    path.with_suffix(".json").write_text(
        json.dumps({"hull": "swath", "draft": "1.1T", "axis": "roll", "angle_deg": 5})
    )
    assert csv_labels(path) == {"hull": "swath", "draft": 1.1, "axis": "roll", "angle_deg": 5.0}
    path.with_suffix(".json").write_text(json.dumps({"hull": "swath"}))
    with pytest.raises(InputError, match="needs JSON with hull, axis, angle_deg"):
        csv_labels(path)


@pytest.mark.slow
def test_cli_campaign_prints_the_table_and_writes_the_report(csv_campaign: Path, tmp_path: Path) -> None:
    result = runner.invoke(app, ["campaign", str(csv_campaign), "--report", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    data_rows = [line for line in result.stdout.splitlines() if line.startswith("| catamaran")]
    assert len(data_rows) == len(DRAFTS) * len(ANGLES_DEG)
    assert (tmp_path / "out" / "campaign.md").read_text().endswith(result.stdout)
    assert (tmp_path / "out" / "hulls_pitch_0.9T.png").stat().st_size > 0


def test_cli_simulate_campaign_writes_the_seeds_matrix(tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        [
            "simulate-campaign",
            str(tmp_path),
            "--hull",
            "swath",
            "--axis",
            "roll",
            "--angle",
            "3",
            "--angle",
            "5",
        ],
    )
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in tmp_path.iterdir())
    assert len(names) == 6 and names[0] == "swath_0.9T_roll_3deg_run01.csv"
    (run,) = read_campaign_runs(tmp_path / "swath_T_roll_5deg_run01.csv")
    assert math.degrees(run.angle[0]) == pytest.approx(5.0, abs=0.1)  # starts at the release
    assert run.rate is not None and run.axis == "roll"
    assert run.meta["hull"] == "swath" and run.meta["draft"] == 1.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["campaign", "/no/such/folder"], "no such file or folder"),
        (["campaign", "{empty}"], "no decay files (.mcap, .csv,"),
        (["campaign", "{unnamed}"], "cannot tell hull, draft, axis and angle"),
        (["campaign", "{notes}"], "not a recording"),
        (["campaign", "{campaign}", "--model", "b1,zz"], "unknown model term"),
        (["campaign", "{campaign}", "--executor", "dask"], "--executor dask needs --scheduler"),
        (["campaign", "{campaign}", "--executor", "spark"], "--executor 'spark' not understood"),
        (["simulate-campaign", "{empty}", "--axis", "yaw"], "axis 'yaw' not understood"),
        (["simulate-campaign", "{empty}", "--draft", "deep"], "draft 'deep' not understood"),
        (["simulate-campaign", "{empty}", "--hull", "ferry"], "unknown hull 'ferry'"),
    ],
)
@pytest.mark.slow
def test_bad_input_is_one_line_and_exit_2(
    args: list[str], message: str, csv_campaign: Path, tmp_path: Path
) -> None:
    (tmp_path / "empty").mkdir()
    (tmp_path / "unnamed").mkdir()
    shutil.copy(csv_campaign / "trimaran_0.9T_pitch_8deg_run01.csv", tmp_path / "unnamed" / "decay1.csv")
    (tmp_path / "notes.md").write_text("hello")
    places = {
        "{empty}": tmp_path / "empty",
        "{unnamed}": tmp_path / "unnamed",
        "{notes}": tmp_path / "notes.md",
        "{campaign}": csv_campaign,
    }
    result = runner.invoke(app, [str(places.get(a, a)) for a in args])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert len(result.output.strip().splitlines()) == 1 and "Traceback" not in result.output


@pytest.mark.slow
def test_a_group_that_cannot_be_fitted_keeps_its_reason(csv_results: list) -> None:
    """One bad condition must not sink the campaign: it is reported, the others are fitted."""
    still = DecayRun(np.arange(0.0, 1.0, 0.01), np.zeros(100), np.zeros(100), axis="pitch", name="still")
    still.meta.update(hull="trimaran", draft=1.0, angle_deg=3.0)
    good = csv_results[0].runs
    results = identify_groups(group_runs([still, *good]))
    failed = [r for r in results if r.fit is None]
    assert [r.key.angle_deg for r in failed] == [3.0] and "does not move" in failed[0].error
    assert "not fitted: still" in markdown_table(results)
    assert sum(r.fit is not None for r in results) == 1


def test_every_campaign_plan_loads_and_names_real_hulls_and_drafts():
    from tankdaq.config.hulls import load_hull, parse_draft
    from tankdaq.config.plans import list_campaign_plans, load_campaign_plan

    plans = list_campaign_plans()
    assert {"seed000-trimaran-catamaran-pitch", "seed001-swath-roll", "seed002-swath-pitch"} <= set(plans)
    for name in plans:
        plan = load_campaign_plan(name)
        for hull in plan.hulls:
            model = load_hull(hull).simulation_model(plan.axis)
            for draft in plan.drafts:
                model.coefficients(parse_draft(draft))  # raises if the hull has no such draft
        assert plan.angles_deg and all(0 < a <= 30 for a in plan.angles_deg)


def test_simulate_campaign_follows_a_plan(tmp_path):
    from typer.testing import CliRunner

    from tankdaq.cli import app

    result = CliRunner().invoke(app, ["simulate-campaign", str(tmp_path), "--plan", "seed001-swath-roll"])
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in tmp_path.glob("*.csv"))
    assert len(names) == 12 and names[0].startswith("swath_0.9T_roll_")
    bad = CliRunner().invoke(app, ["simulate-campaign", str(tmp_path / "x"), "--plan", "nope"])
    assert bad.exit_code == 2 and "seed001-swath-roll" in bad.output


@pytest.mark.slow
def test_a_streamed_campaign_gives_the_serial_rows_and_keeps_no_recording(
    csv_campaign: Path, csv_results: list
) -> None:
    """Workers read the files themselves and send back rows only (``campaign.stream``)."""
    paths = find_recordings([csv_campaign])
    with campaign_executor(jobs=2) as pool:
        scan = scan_campaign(paths, executor=pool)
        rows = sorted(fit_campaign(scan.groups(), executor=pool), key=lambda row: row.key)
    assert scan.skipped == [] and scan.decays == len(paths)
    assert [row.key for row in rows] == [result.key for result in csv_results]
    for row, result in zip(rows, csv_results, strict=True):
        assert row.result is None  # no fit, no runs: the parent holds the table row
        assert row.row == result.summary()
        assert row.warnings == tuple(result.warnings) and row.terms == tuple(result.fit.terms_)


@pytest.mark.slow
def test_on_result_hands_each_whole_fit_over_as_it_comes_and_keeps_only_rows(
    csv_campaign: Path, csv_results: list
) -> None:
    """A consumer (a catalogue) gets every group's fit and runs; the rows yielded hold neither."""
    scan = scan_campaign(find_recordings([csv_campaign]))
    handed: list[GroupResult] = []
    rows = list(fit_campaign(scan.groups(), on_result=handed.append))
    assert [r.key for r in handed] == [row.key for row in rows] == [r.key for r in csv_results]
    assert all(row.result is None for row in rows)
    for mine, serial in zip(handed, csv_results, strict=True):
        assert [run.meta["file"] for run in mine.runs] == [run.meta["file"] for run in serial.runs]
    assert_same_fits(handed, csv_results)


def test_read_campaign_holds_every_decay_and_lists_the_skipped(csv_campaign: Path, tmp_path: Path) -> None:
    """The in-memory reading (a session's few files): the decays of the files that read, in path order."""
    bad = tmp_path / "trimaran_0.9T_pitch_8deg_run09.csv"
    bad.write_text("time_s,angle_deg\n")
    paths = [*find_recordings([csv_campaign]), bad]
    found = read_campaign(paths)
    assert [s.path for s in found.skipped] == [bad]
    assert [run.meta["file"] for run in found.runs] == [
        run.meta["file"] for path in paths[:-1] for run in read_campaign_runs(path)
    ]
