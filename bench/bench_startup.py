"""Start-up: ``tankdaq --help`` and every ``tankdaq COMMAND --help`` against bare ``import numpy, typer``;
and what ``tankdaq identify FILE.csv`` imports (issue 43: the suite starts hundreds of such processes).

Run: .venv/bin/python bench/bench_startup.py   (two to three minutes; ``--identify`` for the second part
alone, half a minute). It writes bench/results/startup.json. Each command line is started
REPEATS times in a fresh process; the figures are the median and the least CPU time (user + system, of the
child process), not wall time, so waiting for a shared machine's cores does not count (its caches still
do: the least is the steadier figure under load); the ratios are against the bare import measured in the
same run, interleaved with the commands. Children run as an installed tankdaq does, from compiled bytecode:
PYTHONDONTWRITEBYTECODE is dropped from their environment and every line runs once before the timing (with it
set, as on this workplace, each start recompiled tankdaq's own modules: about 30 ms of `tankdaq --help`).
"""

from __future__ import annotations

import importlib.util
import os
import resource
import statistics
import subprocess
import sys
import tempfile
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


def child_cpu_s(argv: list[str], cwd: Path | None = None) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, check=True, capture_output=True, env=CHILD_ENV, cwd=cwd)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


#: The heavy libraries a command may import; the identify run says which of them it loaded.
HEAVY = ("pandas", "pyarrow", "scipy.ndimage", "sqlalchemy", "mcap", "matplotlib", "rerun", "h5py")
#: ``tankdaq identify`` in a child that reports, at its end, which of ``HEAVY`` it had loaded. ``BEFORE``
#: preloads what the command imported before issue 43 took it out of the way (pandas, with pyarrow, for
#: a check whether a source was a DataFrame; pymoo, for the GA/PSO searches only): the old cost, measured in
#: the same run as the new. pymoo is no longer a dependency (the searches are numpy): it is preloaded only
#: where it is still installed.
IDENTIFY = """
import atexit, sys
{before}
atexit.register(lambda: print("loaded:", ",".join(m for m in {heavy!r} if m in sys.modules), file=sys.stderr))
from tankdaq.cli import main
sys.argv = ["tankdaq", "identify", {csv!r}]
main()
"""
BEFORE = "import pandas, tankdaq.ident.evolutionary" + (
    ", pymoo.optimize, pymoo.algorithms.soo.nonconvex.ga" if importlib.util.find_spec("pymoo") else ""
)


def identify_imports(repeats: int = 7) -> dict[str, object]:
    """CPU of ``tankdaq identify`` on a held-tilt CSV now and with the old imports preloaded, against the
    bare import; which heavy libraries each loaded."""
    from tankdaq.physics.decay import simulate_decay

    folder = Path(tempfile.mkdtemp(prefix="bench-startup-"))
    csv = folder / "tilt.csv"
    t = [i / 100 for i in range(3000)]
    angle, rate = simulate_decay({"b1": 0.3, "b2": 0.4, "c1": 14.0}, __import__("numpy").array(t), 0.14)
    csv.write_text("time_s,roll_rad,roll_rate_rad_s\n" + "".join(
        f"{a},{b},{c}\n" for a, b, c in zip(t, angle.tolist(), rate.tolist(), strict=True)))  # fmt: skip
    lines = {
        "bare": BASELINE,
        "now": [PYTHON, "-c", IDENTIFY.format(before="", heavy=HEAVY, csv=str(csv))],
        "before": [PYTHON, "-c", IDENTIFY.format(before=BEFORE, heavy=HEAVY, csv=str(csv))],
    }
    loaded = {}
    for name, argv in lines.items():  # bytecode written once; what each loads
        done = subprocess.run(argv, capture_output=True, text=True, env=CHILD_ENV, cwd=folder, check=True)
        loaded[name] = next((line.split(":", 1)[1].strip() for line in done.stderr.splitlines()
                             if line.startswith("loaded:")), "")  # fmt: skip
    times: dict[str, list[float]] = {name: [] for name in lines}
    for _ in range(repeats):
        for name, argv in lines.items():
            times[name].append(child_cpu_s(argv, folder))
    least = {name: min(values) for name, values in times.items()}
    median = {name: statistics.median(values) for name, values in times.items()}
    for name in lines:
        print(
            f"identify {name:<7} {median[name] * 1e3:6.0f} ms CPU median, {least[name] * 1e3:5.0f} least;"
            f" loaded {loaded[name] or '-'}"
        )
    saved = least["before"] - least["now"]
    share = saved / least["before"]
    print(f"identify FILE.csv: {saved * 1e3:.0f} ms CPU less per process than before ({share:.0%})")
    return {
        "what": "tankdaq identify on a 30 s held-tilt CSV, CPU (user+system) of the child",
        "repeats": repeats,
        "cpu_ms_least": {k: round(v * 1e3) for k, v in least.items()},
        "cpu_ms_median": {k: round(v * 1e3) for k, v in median.items()},
        "heavy_loaded": loaded,
        "saved_ms_least": round(saved * 1e3),
        "before_is": f"the same run with `{BEFORE}` first (what identify imported before issue 43)",
    }


def help_startup() -> dict[str, object]:
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
    figures: dict[str, object] = {
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
    return {
        "counts": {"repeats": REPEATS, "command_lines": len(lines) - 1},
        "figures": figures,
        "ratios": {"worst_median_over_baseline": worst, "worst_least_over_baseline": worst_least},
    }


def main() -> None:
    """`--help` start-up against the baseline, then identify's imports before and after (`--identify`: the
    second only)."""
    helps = {} if "--identify" in sys.argv else help_startup()
    identify = identify_imports()
    write_result(
        "startup",
        "CPU time (user + system) in a fresh process: `tankdaq --help`, every `tankdaq COMMAND --help`, and"
        " `tankdaq identify FILE.csv` with today's imports against what it imported before",
        counts=dict(helps.get("counts", {})) | {"identify_repeats": identify["repeats"]},
        figures=dict(helps.get("figures", {})) | {"identify": identify},
        ratios=helps.get("ratios"),
        baseline="`python -c 'import numpy, typer'`, interleaved in the same run; for identify, the same run"
        " with the old imports loaded first",
    )


if __name__ == "__main__":
    main()
