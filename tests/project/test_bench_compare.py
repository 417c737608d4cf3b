"""``bench/run_all.py --compare OLD NEW`` (issue 43 item 7): two result sets written by the benches' own
helper (``bench/benchjson.write_result``), compared figure by figure, from folders and from git revisions
(a throwaway repository, read with ``git show`` as a lab reads its history). No timings: the figures are
made-up numbers whose relative changes are known."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RUN_ALL = ROOT / "bench" / "run_all.py"
sys.path.insert(0, str(ROOT / "bench"))

from benchjson import flatten, write_result  # noqa: E402


def write_set(
    folder: Path, decode_rate: float, fit_ms: float, *, quick: bool = False, extra: bool = False
) -> None:
    """Two benches' results as the scripts write them (a third, ``extra``, only in one set)."""
    write_result(
        "decode",
        "decoding throughput",
        counts={"frames": 1000},
        figures={"decay": {"batch_m_frames_per_s_cpu": decode_rate}, "gone_or_new": 1.0 if extra else None},
        ratios={"decay": {"batch_cpu_after_over_before": decode_rate / 4.0}},
        baseline="a decoder of the same run",
        folder=folder,
        quick=quick,
    )
    write_result("ident", "fit time", counts={"repeats": 40}, figures={"oe_ms_cpu": fit_ms}, folder=folder)
    if extra:
        write_result("export", "export", counts={"samples": 10}, figures={"csv": {"mb": 1.5}}, folder=folder)


def compare(old: str, new: str, cwd: Path = ROOT, *options: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(RUN_ALL), "--compare", old, new, *options],
        cwd=cwd,
        capture_output=True,
        text=True,
    )


@pytest.fixture(scope="module")
def two_sets(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    old, new = tmp_path_factory.mktemp("old"), tmp_path_factory.mktemp("new")
    write_set(old, decode_rate=4.0, fit_ms=20.0)
    write_set(new, decode_rate=5.0, fit_ms=15.0, extra=True)
    return old, new


def test_a_result_is_one_json_object_with_its_machine_date_and_counts(two_sets: tuple[Path, Path]) -> None:
    old, _ = two_sets
    result = json.loads((old / "decode.json").read_text())
    assert result["topic"] == "decode" and result["counts"] == {"frames": 1000}
    assert result["cpu_count"] >= 1 and result["date"].startswith("20") and result["quick"] is False
    assert result["baseline"] == "a decoder of the same run"
    assert not list(old.glob(".*.tmp")), "written through a temporary name that is renamed into place"
    assert flatten(result) == {
        "counts.frames": 1000.0,
        "figures.decay.batch_m_frames_per_s_cpu": 4.0,
        "ratios.decay.batch_cpu_after_over_before": 1.0,
    }


@pytest.mark.slow
def test_compare_two_folders_says_each_figures_relative_change(two_sets: tuple[Path, Path]) -> None:
    old, new = two_sets
    done = compare(str(old), str(new))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    rate = next(line for line in lines if "figures.decay.batch_m_frames_per_s_cpu" in line)
    assert rate.split()[1:] == ["4", "->", "5", "+25.0%"]
    fit = next(line for line in lines if "figures.oe_ms_cpu" in line)
    assert fit.split()[-1] == "-25.0%"
    assert next(line for line in lines if "counts.frames" in line).split()[-1] == "="
    assert "(new)" in next(line for line in lines if "figures.gone_or_new" in line)
    assert "export: only in NEW" in lines
    changed = compare(str(old), str(new), ROOT, "--changed").stdout
    assert "counts.frames" not in changed and "figures.oe_ms_cpu" in changed


def test_compare_says_when_the_counts_are_not_like_for_like(
    tmp_path: Path, two_sets: tuple[Path, Path]
) -> None:
    old, _ = two_sets
    write_set(tmp_path, decode_rate=2.0, fit_ms=20.0, quick=True)
    done = compare(str(old), str(tmp_path))
    assert "quick False -> True: the counts differ" in done.stdout
    assert next(line for line in done.stdout.splitlines() if "batch_m_frames" in line).split()[-1] == "-50.0%"


@pytest.mark.slow
def test_compare_two_git_revisions_reads_their_committed_results(
    tmp_path: Path, two_sets: tuple[Path, Path]
) -> None:
    old, new = two_sets
    results = tmp_path / "bench" / "results"

    def git(*args: str) -> None:
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)

    git("init", "-q")
    for number, folder in enumerate((old, new)):
        shutil.rmtree(results, ignore_errors=True)
        git("add", "-A")  # out of the index first: a same-sized file of the same second looks unchanged
        shutil.copytree(folder, results)
        git("add", "-A")
        git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", f"results {number}")
    shutil.rmtree(results)  # the revisions alone hold them now
    by_revision = compare("HEAD~1", "HEAD", cwd=tmp_path)
    assert by_revision.returncode == 0, by_revision.stderr
    assert by_revision.stdout == compare(str(old), str(new)).stdout
    mixed = compare("HEAD~1", str(new), cwd=tmp_path)  # a revision against a folder
    assert "+25.0%" in mixed.stdout


def test_a_source_that_is_neither_folder_nor_revision_is_refused_in_one_line(tmp_path: Path) -> None:
    done = compare(str(tmp_path / "nowhere"), str(tmp_path))
    assert done.returncode != 0
    assert "neither a results folder nor a git revision" in done.stderr
    assert "Traceback" not in done.stderr
