"""Run the benchmarks (``make bench``), or compare two result sets figure by figure.

    python bench/run_all.py [--quick] [NAME ...]     every bench_*.py (or those whose name holds a NAME),
                                                     each writing bench/results/<topic>.json
    python bench/run_all.py --compare OLD NEW        OLD, NEW: a results folder, or a git revision whose
                                                     bench/results/ is read with ``git show`` (the repository
                                                     of the current folder)

``--quick`` runs each script with its small counts (``QUICK_ARGS``; ``TANKDAQ_BENCH_QUICK=1`` marks their
results ``"quick": true``; a script without small counts runs as it is);
a script's printed table goes to ``$TMPDIR/tankdaq-bench-logs/<script>.log``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchjson import flatten, load_folder, load_revision

BENCH = Path(__file__).resolve().parent
#: Small counts per script for ``--quick`` (a script not named runs as it is).
QUICK_ARGS: dict[str, list[str]] = {
    "bench_budget_coverage.py": ["--campaigns", "20"],
    "bench_campaign_scale.py": ["--sizes", "36", "--repeats", "1", "--no-command"],
    "bench_catalogue_campaign.py": ["--n", "36", "--repeats", "1"],
    "bench_clipping.py": ["5"],
    "bench_csv_import.py": ["200000"],
    "bench_decode.py": ["--frames", "100000"],
    "bench_decoder_fuzz.py": ["--messages", "500"],
    "bench_export.py": ["36000"],
    "bench_first_run.py": ["--repeats", "1"],
    "bench_hidden_effects.py": ["--draws", "3"],
    "bench_kernel_build.py": ["--builds", "1", "--rounds", "3"],
    "bench_memory_day.py": ["--hours", "1"],
    "bench_mt_manager.py": ["20000"],
    "bench_question_pause.py": ["--pause", "10"],
    "bench_read_loop.py": ["--decays", "5"],
    "bench_record.py": ["--seconds", "30", "--repeats", "1"],
    "bench_ident.py": ["--runs", "40"],
    "bench_reference_integrator.py": ["--repeats", "1"],
    "bench_release_bias.py": ["--releases", "20"],
    "bench_release_sway.py": ["--releases", "20", "--baseline", "none"],
    "bench_repeats.py": ["--sizes", "36,200"],
    "bench_runaway.py": ["--cap", "20", "--repeats", "1"],
    "bench_two_cores.py": ["--repeats", "1"],
    "bench_web_memory.py": ["--decays", "10"],
}


def run(names: list[str], quick: bool) -> int:
    """Each chosen script in its own process, in turn, with a progress bar; 1 if any failed."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    scripts = [
        path for path in sorted(BENCH.glob("bench_*.py")) if not names or any(n in path.name for n in names)
    ]
    logs = Path(tempfile.gettempdir()) / "tankdaq-bench-logs"
    logs.mkdir(parents=True, exist_ok=True)
    failed: list[str] = []
    columns = (TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"))
    with Progress(*columns, TimeElapsedColumn()) as progress:
        task = progress.add_task("benchmarks", total=len(scripts))
        for script in scripts:
            progress.update(task, description=script.name)
            args = QUICK_ARGS.get(script.name, []) if quick else []
            env = os.environ | ({"TANKDAQ_BENCH_QUICK": "1"} if args else {})  # small counts run: said so
            started = time.perf_counter()
            with (logs / f"{script.stem}.log").open("w") as log:
                code = subprocess.call(
                    [sys.executable, str(script), *args], stdout=log, stderr=subprocess.STDOUT, env=env
                )
            took = time.perf_counter() - started
            progress.console.print(
                f"{script.name}: {'ok' if code == 0 else f'FAILED ({code})'} in {took:.0f} s"
            )
            if code:
                failed.append(script.name)
            progress.advance(task)
    if failed:
        print(f"failed: {', '.join(failed)} (their logs are in {logs})")
    return 1 if failed else 0


def load(source: str) -> dict[str, dict[str, Any]]:
    """A result set from a folder, else from a git revision of the current folder's repository."""
    folder = Path(source)
    if folder.is_dir():
        return load_folder(folder)
    try:
        return load_revision(source, Path.cwd())
    except subprocess.CalledProcessError as error:
        why = error.stderr.strip()
        raise SystemExit(
            f"{source}: neither a results folder nor a git revision with bench/results ({why})"
        ) from None


def _change(old: float, new: float) -> str:
    if old == new:
        return "="
    if old == 0:
        return "new" if new else "="
    return f"{(new - old) / abs(old):+.1%}"


def compare(
    old: dict[str, dict[str, Any]], new: dict[str, dict[str, Any]], changed: bool = False
) -> list[str]:
    """The lines that say, topic by topic and figure by figure, how NEW differs from OLD (``changed``: only
    the figures that differ)."""
    lines: list[str] = []
    for topic in sorted(old.keys() | new.keys()):
        if topic not in new or topic not in old:
            lines.append(f"{topic}: only in {'OLD' if topic in old else 'NEW'}")
            continue
        before, after = old[topic], new[topic]
        when = f"{before.get('date', '?')} -> {after.get('date', '?')}"
        lines.append(f"{topic} ({when}, cpu_count {before.get('cpu_count')} -> {after.get('cpu_count')})")
        if before.get("quick") != after.get("quick"):
            quick = f"{before.get('quick')} -> {after.get('quick')}"
            lines.append(f"  quick {quick}: the counts differ, the figures are not like for like")
        a, b = flatten(before), flatten(after)
        width = max((len(name) for name in a.keys() | b.keys()), default=0)
        for name in sorted(a.keys() | b.keys()):
            if name not in b:
                lines.append(f"  {name:{width}s}  {a[name]:>12.6g} -> (gone)")
            elif name not in a:
                lines.append(f"  {name:{width}s}  {'(new)':>12s} -> {b[name]:<12.6g}")
            else:
                change = _change(a[name], b[name])
                if changed and change == "=":
                    continue
                lines.append(f"  {name:{width}s}  {a[name]:>12.6g} -> {b[name]:<12.6g} {change}")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="run only the scripts whose name holds one of these")
    parser.add_argument("--quick", action="store_true", help="small counts (QUICK_ARGS)")
    parser.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"), help="compare two result sets")
    parser.add_argument("--changed", action="store_true", help="with --compare: only the figures that differ")
    args = parser.parse_args()
    if args.compare:
        print("\n".join(compare(load(args.compare[0]), load(args.compare[1]), args.changed)))
        return 0
    return run(args.names, args.quick)


if __name__ == "__main__":
    sys.exit(main())
