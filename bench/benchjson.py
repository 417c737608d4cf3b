"""One JSON object per bench script, ``bench/results/<topic>.json``, and result sets read back.

Every ``bench_*.py`` ends with :func:`write_result`: what was measured, the counts, the figures (numbers,
named with their unit), ratios against a baseline measured in the same run where the script compares,
``os.cpu_count()``, the load and the date. ``run_all.py --compare`` reads two sets with
:func:`load_folder` or :func:`load_revision` and compares them figure by figure (:func:`flatten`).
"""

from __future__ import annotations

import datetime
import json
import os
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"
#: The keys that say where and when; every other number is a figure a comparison shows.
META = (
    "topic",
    "measured",
    "baseline",
    "quick",
    "cpu_count",
    "load_1min",
    "date",
    "commit",
    "python",
    "note",
)
#: Set by ``run_all.py --quick``: each script runs its small counts (the figures say so: ``"quick": true``).
QUICK = os.environ.get("TANKDAQ_BENCH_QUICK") == "1"


def _commit() -> str | None:
    done = subprocess.run(
        ["git", "-C", str(RESULTS.parent), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    )
    return done.stdout.strip() or None


def write_result(
    topic: str,
    measured: str,
    *,
    counts: Mapping[str, Any],
    figures: Mapping[str, Any],
    ratios: Mapping[str, Any] | None = None,
    baseline: str | None = None,
    note: str | None = None,
    folder: Path | None = None,
    quick: bool = QUICK,
) -> Path:
    """Write ``<folder>/<topic>.json`` (``bench/results/`` by default) through a temporary name; return it.

    ``figures`` and ``ratios`` may nest dicts (one per case); a ratio is new over baseline, both from this
    run, and ``baseline`` says what the baseline is.
    """
    result: dict[str, Any] = {"topic": topic, "measured": measured, "counts": dict(counts)}
    result["figures"] = dict(figures)
    if ratios:
        result["ratios"] = dict(ratios)
    if baseline:
        result["baseline"] = baseline
    if note:
        result["note"] = note
    result |= {
        "quick": quick,
        "cpu_count": os.cpu_count(),
        "load_1min": round(os.getloadavg()[0], 2),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "commit": _commit(),
        "python": sys.version.split()[0],
    }
    target = (folder or RESULTS) / f"{topic}.json"
    target.parent.mkdir(parents=True, exist_ok=True)
    temporary = target.with_name(f".{target.name}.tmp")
    temporary.write_text(json.dumps(result, indent=1, default=_plain) + "\n")
    temporary.replace(target)
    print(f"-> {target}", flush=True)
    return target


def _plain(value: Any) -> Any:
    """numpy scalars and arrays, paths: as JSON knows them."""
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def flatten(result: Mapping[str, Any]) -> dict[str, float]:
    """``{"figures.case.name": number}`` of every number in a result but its meta keys (bools are not)."""
    found: dict[str, float] = {}

    def visit(value: Any, name: str) -> None:
        if isinstance(value, Mapping):
            for key, inner in value.items():
                visit(inner, f"{name}.{key}" if name else str(key))
        elif isinstance(value, int | float) and not isinstance(value, bool):
            found[name] = float(value)

    visit({key: value for key, value in result.items() if key not in META}, "")
    return found


def load_folder(folder: Path) -> dict[str, dict[str, Any]]:
    """``{topic: result}`` of every ``*.json`` in a results folder."""
    return {path.stem: json.loads(path.read_text()) for path in sorted(folder.glob("*.json"))}


def load_revision(revision: str, repo: Path) -> dict[str, dict[str, Any]]:
    """``{topic: result}`` of ``bench/results/*.json`` as committed at a git revision of ``repo``."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(repo), *args], capture_output=True, text=True, check=True
        ).stdout

    names = git("ls-tree", "--name-only", f"{revision}:bench/results").split()
    return {
        Path(name).stem: json.loads(git("show", f"{revision}:bench/results/{name}"))
        for name in names
        if name.endswith(".json")
    }
