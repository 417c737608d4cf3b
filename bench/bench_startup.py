"""Start-up: ``tankdaq --help`` and every ``tankdaq COMMAND --help`` against bare ``import numpy, typer``.

Run: .venv/bin/python bench/bench_startup.py   (two to three minutes). Each command line is started
REPEATS times in a fresh process; the figures are the median and the least CPU time (user + system, of the
child process), not wall time, so waiting for a shared machine's cores does not count (its caches still
do: the least is the steadier figure under load); the ratios are against the bare import measured in the
same run, interleaved with the commands. Children run as an installed tankdaq does, from compiled bytecode:
PYTHONDONTWRITEBYTECODE is dropped from their environment and every line runs once before the timing (with it
set, as on this workplace, each start recompiled tankdaq's own modules: about 30 ms of `tankdaq --help`).
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

import typer

from benchjson import write_result
from tankdaq.cli import app

REPEATS = 11
PYTHON = sys.executable
TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))
BASELINE = [PYTHON, "-c", "import numpy, typer"]


def command_paths() -> list[list[str]]:
    """Every command and sub-command of the typer app, as argument lists."""
    paths: list[list[str]] = []

    def walk(command: object, prefix: list[str]) -> None:
        paths.append(prefix)
        for name, sub in sorted(getattr(command, "commands", {}).items()):  # typer's own click
            walk(sub, [*prefix, name])

    walk(typer.main.get_command(app), [])
    return paths


CHILD_ENV = {**{k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}, "COLUMNS": "100"}


def child_cpu_s(argv: list[str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, check=True, capture_output=True, env=CHILD_ENV)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; {sys.version.split()[0]}")
    lines = [BASELINE] + [[TANKDAQ, *path, "--help"] for path in command_paths()]
    times: dict[int, list[float]] = {i: [] for i in range(len(lines))}
    for argv in lines:  # bytecode written once, as pip does at install
        child_cpu_s(argv)
    for _ in range(REPEATS):  # interleaved: a change in the machine's load touches every line alike
        for i, argv in enumerate(lines):
            times[i].append(child_cpu_s(argv))
    base, base_least = statistics.median(times[0]), min(times[0])
    label = "python -c 'import numpy, typer'"
    print(f"{label:<44} {base * 1e3:6.0f} ms CPU median, {base_least * 1e3:4.0f} least (baseline)")
    worst = worst_least = 0.0
    figures = {
        "baseline import numpy, typer": {"median_ms_cpu": base * 1e3, "least_ms_cpu": base_least * 1e3}
    }
    for i, argv in enumerate(lines[1:], start=1):
        cpu, least = statistics.median(times[i]), min(times[i])
        worst, worst_least = max(worst, cpu / base), max(worst_least, least / base_least)
        figures[" ".join(["tankdaq", *argv[1:]])] = {"median_ms_cpu": cpu * 1e3, "least_ms_cpu": least * 1e3}
        print(
            f"{' '.join(['tankdaq', *argv[1:]]):<44} {cpu * 1e3:6.0f} ms CPU median {cpu / base:4.2f}x, "
            f"{least * 1e3:4.0f} least {least / base_least:4.2f}x"
        )
    print(f"worst ratio to the baseline: {worst:.2f}x median, {worst_least:.2f}x least (target <= 1.5x)")
    write_result(
        "startup",
        "CPU time (user + system) of `tankdaq --help` and every `tankdaq COMMAND --help` in a fresh process",
        counts={"repeats": REPEATS, "command_lines": len(lines) - 1},
        figures=figures,
        ratios={"worst_median_over_baseline": worst, "worst_least_over_baseline": worst_least},
        baseline="`python -c 'import numpy, typer'`, interleaved in the same run",
    )


if __name__ == "__main__":
    main()
