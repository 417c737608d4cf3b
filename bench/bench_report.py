"""The CPU of one ``tankdaq report FOLDER --hull swath.toml --out DIR`` (three simulated swath roll decays,
fixed seed) made by this tree's code, against the same report made by main's code in the same run (issue
43: the suite makes about fifteen reports, a lab one after each campaign).

Run: .venv/bin/python bench/bench_report.py   (about two minutes; ``--repeats N``, default 5). It writes
bench/results/report.json. main's ``src`` and ``configs`` are exported with ``git archive main src configs``
into a temporary folder and run with PYTHONPATH pointing there; this tree's with PYTHONPATH=src. Each
report is a fresh process (as a user runs it), the two codes interleaved, after one run each to compile
bytecode; the figure is the CPU time (user + system) of the child, not wall time, so waiting for a shared
machine's cores does not count. Every run's ``--json`` document must equal main's but for the time made:
the same numbers shown.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchjson import QUICK, write_result

ROOT = Path(__file__).resolve().parents[1]
#: ``tankdaq`` as its console script runs it, on whichever ``src`` PYTHONPATH names.
CLI = [
    sys.executable,
    "-c",
    "import sys; from tankdaq.cli import main; sys.argv[0] = 'tankdaq'; sys.exit(main())",
]
ANGLES_DEG = (5.0, 8.0, 11.0)


def decays(folder: Path) -> Path:
    """Three simulated swath roll decays (MCAP recordings), seed 3, and the swath hull file beside them
    (both codes read the same file, so the provenance names the same path): the report's input."""
    from tankdaq.campaign.synthetic import write_simulated_campaign

    write_simulated_campaign(folder, ["swath"], "roll", [1.0], list(ANGLES_DEG), "mcap", seed=3)
    (folder.parent / "swath.toml").write_bytes((ROOT / "configs" / "hulls" / "swath.toml").read_bytes())
    return folder


def main_src(work: Path) -> Path:
    """main's ``src`` and ``configs`` (the hulls beside it) exported into ``work`` (``git archive``: no
    worktree, no checkout)."""
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", "main", "src", "configs"], capture_output=True, check=True
    )
    subprocess.run(["tar", "-x", "-C", str(work)], input=archive.stdout, check=True)
    return work / "src"


def report_cpu(src: Path, inputs: Path, work: Path) -> tuple[float, dict[str, Any], dict[str, int]]:
    """One report in a fresh process on ``src``'s code: its CPU seconds, its JSON document (without the
    time made) and the sizes of the files it wrote."""
    env = {
        k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "OPENBLAS_NUM_THREADS")
    }
    env["PYTHONPATH"] = str(src)
    work.mkdir()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(
        [*CLI, "report", str(inputs), "--hull", str(inputs.parent / "swath.toml"), "--out", "out", "--json"],
        cwd=work, env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    document = json.loads(done.stdout)
    document.pop("made_utc")
    sizes = {path.name: path.stat().st_size for path in sorted((work / "out").iterdir())}
    return cpu, document, sizes


def summary(values: list[float]) -> dict[str, Any]:
    return {
        "cpu_s": [round(v, 3) for v in values],
        "median_s": round(statistics.median(values), 3),
        "least_s": round(min(values), 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2 if QUICK else 5)
    repeats = parser.parse_args().repeats
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        inputs = decays(work / "decays")
        codes = {"this": ROOT / "src", "main": main_src(work)}
        cpu: dict[str, list[float]] = {name: [] for name in codes}
        documents: dict[str, dict[str, Any]] = {}
        sizes: dict[str, dict[str, int]] = {}
        for name, src in codes.items():  # bytecode compiled, caches warm: not counted
            _, documents[name], sizes[name] = report_cpu(src, inputs, work / f"warm-{name}")
        if documents["this"] != documents["main"]:
            raise SystemExit("this tree's report shows other numbers than main's: not comparable")
        for run in range(repeats):
            for name, src in codes.items():
                seconds, document, _ = report_cpu(src, inputs, work / f"{name}-{run}")
                assert document == documents["main"], "a rerun showed other numbers"
                cpu[name].append(seconds)
                print(f"{name:5s} run {run + 1}/{repeats}: {seconds:.2f} s CPU", flush=True)
    pairs = [new / old for new, old in zip(cpu["this"], cpu["main"], strict=True)]
    ratios = {
        "median_this_over_main": round(statistics.median(cpu["this"]) / statistics.median(cpu["main"]), 3),
        "least_this_over_main": round(min(cpu["this"]) / min(cpu["main"]), 3),
        "pair_ratio_min": round(min(pairs), 3),
        "pair_ratio_max": round(max(pairs), 3),
    }
    print(json.dumps(ratios))
    write_result(
        "report",
        "CPU seconds (user + system) of one `tankdaq report FOLDER --hull swath.toml --out DIR --json` "
        f"process on {len(ANGLES_DEG)} simulated swath roll decays (MCAP, seed 3), this tree against main",
        counts={"decays": len(ANGLES_DEG), "repeats": repeats},
        figures={"this": summary(cpu["this"]), "main": summary(cpu["main"]), "file_bytes": sizes},
        ratios=ratios,
        baseline="main's src (git archive main src configs), run in the same process pairs, interleaved",
        note="the two JSON documents are equal but for made_utc (checked every run)",
    )


if __name__ == "__main__":
    main()
