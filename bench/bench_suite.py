"""The maintainers' loop: what ``make check`` costs (issue 43: under a minute on this 2-core machine), and,
with ``--full``, what the whole suite of ``make test`` costs (under ten minutes), with its workers.

Run from the repository: .venv/bin/python bench/bench_suite.py [--full]. It writes bench/results/suite.json.
Each step runs as ``make check`` runs it (the lint with its warm caches, the source compiled, the kernels
prepared, then ``pytest -n auto --dist loadfile -m "not slow"``); the figures are each step's wall time and
the CPU time (user + system) of it and its children, with the tests counted from pytest's last line; for
the whole suite also the seconds the machine's cores were busy (the browsers' renderers are not all
reaped by a test, so only this counts them). The
baseline, measured in the same run, is collecting the tests (``pytest --collect-only``, one process): the
ratio says how many collections the step costs, a figure that keeps when the machine's speed does not.
"""

from __future__ import annotations

import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

from benchjson import write_result

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
PYTEST = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider"]
STEPS = {
    "lint": [
        [str(BIN / "ruff"), "check", "-q", "src", "tests", "bench", "tools"],
        [str(BIN / "ruff"), "format", "--check", "-q", "src", "tests", "bench", "tools"],
        [str(BIN / "mypy")],
    ],
    "prepare": [
        [sys.executable, "-m", "compileall", "-q", "src"],
        [sys.executable, "-m", "tankdaq.prepare", "--jit"],
    ],
    "tests_not_slow": [
        [*PYTEST, "-n", "auto", "--dist", "loadfile", "--no-loadscope-reorder", "-m", "not slow", "-q"]
    ],
}
#: ``make test``'s pytest: its worker count from tools/pytest_workers.py, as the Makefile takes it.
WORKERS = subprocess.run(
    [sys.executable, str(ROOT / "tools" / "pytest_workers.py")], capture_output=True, text=True, check=True
).stdout.strip()
FULL = [*PYTEST, "-n", WORKERS, "--dist", "loadfile", "--no-loadscope-reorder", "-q"]
BASELINE = [*PYTEST, "--collect-only", "-q"]


def machine_busy_s() -> float:
    """The CPU seconds this machine's cores have been busy since boot (Linux's /proc/stat; NaN elsewhere):
    it counts what a step's children leave behind them too (a browser's renderers, reparented when their
    browser is killed, are never reaped by the step), and whatever else runs."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
    except OSError:
        return float("nan")
    user, nice, system, _idle, _iowait, irq, softirq = (int(f) for f in fields[:7])
    return (user + nice + system + irq + softirq) / os.sysconf("SC_CLK_TCK")  # not steal: the host's


def timed(commands: list[list[str]]) -> tuple[float, float, float, str]:
    """Wall, CPU (its own and its reaped children's) and the machine's busy seconds of ``commands`` run one
    after another (each must pass), and the last output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    busy = machine_busy_s()
    start = time.monotonic()
    said = ""
    for argv in commands:
        done = subprocess.run(argv, cwd=ROOT, env=ENV, capture_output=True, text=True)
        said = done.stdout + done.stderr
        if done.returncode != 0:
            raise SystemExit(f"bench_suite: {' '.join(argv[:4])} failed:\n{said[-3000:]}")
    wall = time.monotonic() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, machine_busy_s() - busy, said


def passed(said: str) -> int:
    found = re.search(r"(\d+) passed", said)
    return int(found[1]) if found else 0


def main(full: bool) -> None:
    base_wall, base_cpu, _, _ = timed([BASELINE])
    figures: dict[str, dict[str, float]] = {"collect_only": {"wall_s": base_wall, "cpu_s": base_cpu}}
    counts: dict[str, int] = {}
    steps = dict(STEPS) | ({"tests_all": [FULL]} if full else {})
    for name, commands in steps.items():
        wall, cpu, busy, said = timed(commands)
        figures[name] = {"wall_s": round(wall, 1), "cpu_s": round(cpu, 1)}
        if name == "tests_all":
            figures[name]["machine_busy_s"] = round(busy, 1)
        if name.startswith("tests"):
            counts[name] = passed(said)
        print(f"{name}: {wall:.1f} s wall, {cpu:.1f} s CPU, the machine busy {busy:.1f} s", flush=True)
    check = {k: sum(figures[s][k] for s in STEPS) for k in ("wall_s", "cpu_s")}
    figures["make_check"] = {k: round(v, 1) for k, v in check.items()}
    print(f"make check: {check['wall_s']:.1f} s wall, {check['cpu_s']:.1f} s CPU (target: 60 s wall)")
    write_result(
        "suite",
        "make check's steps (and with --full the whole pytest run of make test): wall and CPU seconds",
        counts=counts,
        figures=figures,
        ratios={"make_check_cpu_over_collect": round(check["cpu_s"] / base_cpu, 2)},
        baseline="pytest --collect-only in one process, measured in the same run",
    )


if __name__ == "__main__":
    main("--full" in sys.argv[1:])
