"""Recorder CPU share at 100 and 400 Hz (live fit included) and replay speed of a 10-minute file.

CPU share: the simulated MTi-G runs in its own process (``tankdaq simulate``, real time) so
only the recorder's own work is counted: process CPU time of this process over wall time,
while it records decays with release detection, MCAP writing, live refits and no viewer.

Replay: a 10-minute capture (a decay test every 35 s) is recorded into one MCAP, then
``replay_recording(speed=None)`` re-decodes, re-detects and re-identifies all of it (CPU time: the
machine is shared), twice in a fresh process: the first run includes loading the compiled kernels;
beside the same of an earlier commit when BASELINE_SRC names its src/ folder. And the command
``tankdaq replay`` of one 17 s decay end to end (process start and imports included), beside the
same command of an earlier commit when BASELINE_SRC names its src/ folder (``git archive COMMIT src``).

Run: .venv/bin/python bench/bench_record.py [replay] [--seconds 75] [--repeats 3]   ("replay": skip the two
CPU-share runs of --seconds each)

BLAS runs single-threaded here, as the ``tankdaq`` command sets it (``tankdaq.cli``): the fit's
small QRs on a threaded OpenBLAS leave its threads spinning, which doubles the CPU time of an
in-process replay (1.55 s against 0.87 s) for about the same wall time.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchjson import write_result
from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator import SimulatedMTi
from tankdaq.store.writer import RecordingWriter

#: ``tankdaq`` of whichever tankdaq PYTHONPATH gives (the venv's console script ignores it).
TANKDAQ = [sys.executable, "-c", "from tankdaq.cli import main; main()"]


def cpu_share(rate_hz: int, seconds: float, out: Path) -> tuple[float, int, int]:
    """Record for ``seconds`` of wall time against a real-time simulator in another process: CPU share,
    samples, decays (their files stay in ``out``)."""
    baud = 115200 if rate_hz <= 100 else 460800
    sim = subprocess.Popen(
        [*TANKDAQ, "simulate", "--rate", str(rate_hz), "--baud", str(baud), "--runs", "50", "--seed", "4"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().strip()
        settings = RecordSettings(
            port=port,
            draft=1.0,
            angle_deg=8.0,
            hull="swath",
            rate_hz=rate_hz,
            baud=baud,
            out_dir=out,
            viewer="none",
        )
        daemon = RecordDaemon(settings)
        samples = 0
        deadline: float | None = None

        def status(st) -> None:
            nonlocal samples
            samples = st.samples
            if deadline is not None and time.monotonic() > deadline:
                raise KeyboardInterrupt

        daemon.on_status = status
        cpu0, wall0 = time.process_time(), time.monotonic()
        deadline = wall0 + seconds
        daemon.run()
        cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
        return cpu / wall, samples, len(daemon.outcomes)
    finally:
        sim.terminate()
        sim.wait(timeout=10)


def mcap_mb(folder: Path) -> float:
    """The size of every MCAP under ``folder`` (a decay that is still open at the stop counts too)."""
    return sum(path.stat().st_size for path in folder.rglob("*.mcap")) / 1e6


def ten_minute_file(folder: Path, seconds: float = 600.0, runs: int = 18) -> Path:
    """Record 10 minutes of simulated decay tests (raw bytes and samples) into one MCAP (18 x 35 s = 10.5
    min of scenario); or ``seconds`` of ``runs`` decays."""
    scenario = hull_scenario(hull="swath", draft=1.0, angle_deg=8.0, runs=runs, seed=7)
    path = folder / f"simulated_{seconds:g}s.mcap"
    with SimulatedMTi(scenario, speed=40.0) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        with RecordingWriter(path, {"axis": "roll", "angle_nominal_deg": 8.0, "hull": "swath"}, {}) as writer:
            first = None
            while True:
                block = driver.read_block()
                writer.write_raw(block.raw, int(block.host_t * 1e9))
                writer.write_samples(block.samples)
                if block.samples.size:
                    first = first if first is not None else float(block.samples["t"][0])
                    if float(block.samples["t"][-1]) - first >= seconds:
                        break
    return path


def replay_command(path: Path, seconds: float) -> dict[str, float]:
    """``tankdaq replay FILE --speed max --viewer none`` end to end, process start and imports included,
    5 times; with BASELINE_SRC (the src/ folder of a ``git archive`` of an earlier commit) that code's
    command in turn with it, in the same run."""
    trees = [("this tree", os.environ.get("PYTHONPATH"))]
    if os.environ.get("BASELINE_SRC"):
        trees.append(("baseline", os.environ["BASELINE_SRC"]))
    cpus: dict[str, list[float]] = {tree: [] for tree, _ in trees}
    walls: dict[str, list[float]] = {tree: [] for tree, _ in trees}
    for _ in range(5):
        for tree, src in trees:
            env = {**os.environ, "PYTHONPATH": src} if src else dict(os.environ)
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            wall = time.perf_counter()
            subprocess.run(
                [*TANKDAQ, "replay", path, "--speed", "max", "--viewer", "none"],
                check=True,
                capture_output=True,
                env=env,
            )
            walls[tree].append(time.perf_counter() - wall)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus[tree].append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    figures = {}
    for tree, _ in trees:
        cpu, wall = statistics.median(cpus[tree]), statistics.median(walls[tree])
        figures[f"{tree}: cpu_s"], figures[f"{tree}: wall_s"] = cpu, wall
        print(
            f"tankdaq replay of one {seconds:g} s decay ({tree}): median {cpu:.2f} s CPU = "
            f"{seconds / cpu:.1f}x real time (wall {wall:.2f} s = {seconds / wall:.1f}x)"
        )
    return figures


#: ``replay_recording`` of a file twice in one fresh process: CPU time of each (the first includes
#: loading the kernels), decays re-detected and refitted, median R2.
IN_PROCESS = """
import sys, time, json
import numpy as np
from tankdaq.acquire.replay import replay_recording
out = []
for _ in range(2):
    cpu, wall = time.process_time(), time.perf_counter()
    outcomes = replay_recording(sys.argv[1], speed=None)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    fits = [o.fit for o in outcomes if o.fit is not None]
    out.append([cpu, wall, len(outcomes), len(fits), float(np.median([f.r2_angle for f in fits]))])
print(json.dumps(out))
"""


def replay_in_process(path: Path, seconds: float, repeats: int = 3) -> dict[str, float]:
    """``replay_recording(speed=None)`` of the whole file, in a fresh process per tree (this one and,
    with BASELINE_SRC, an earlier commit's), interleaved ``repeats`` times: cold (kernels loaded in
    the run) and warm (the same process again)."""
    trees = [("this tree", os.environ.get("PYTHONPATH"))]
    if os.environ.get("BASELINE_SRC"):
        trees.append(("baseline", os.environ["BASELINE_SRC"]))
    runs: dict[str, list[list[list[float]]]] = {tree: [] for tree, _ in trees}
    for _ in range(repeats):
        for tree, src in trees:
            env = {**os.environ, "PYTHONPATH": src} if src else dict(os.environ)
            command = [sys.executable, "-c", IN_PROCESS, str(path)]
            done = subprocess.run(command, check=True, capture_output=True, text=True, env=env)
            runs[tree].append(json.loads(done.stdout.strip().splitlines()[-1]))
    figures = {}
    for tree, _ in trees:
        for index, label in ((0, "cold: kernels loaded in the run"), (1, "warm: the same process again")):
            cpu = statistics.median(run[index][0] for run in runs[tree])
            wall = statistics.median(run[index][1] for run in runs[tree])
            _, _, decays, fitted, r2 = runs[tree][0][index]
            figures[f"{tree}, {label.split(':')[0]}: cpu_s"] = cpu
            figures[f"{tree}, {label.split(':')[0]}: times_real_time_cpu"] = seconds / cpu
            figures[f"{tree}, {label.split(':')[0]}: decays_refitted"] = fitted
            print(
                f"replay of {seconds:g} s at max speed in-process ({tree}, {label}): "
                f"median {cpu:.2f} s CPU = {seconds / cpu:.0f}x real time (wall {wall:.2f} s), "
                f"{decays} decays re-detected, {fitted} refitted (median R2 {r2:.4f})"
            )
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", nargs="?", choices=("replay",), help="the replay figures alone")
    parser.add_argument("--seconds", type=float, default=75.0, help="wall time of each CPU-share run")
    parser.add_argument("--repeats", type=int, default=3, help="in-process replays of the 10-minute file")
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {platform.python_version()}")
    figures: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        figures["replay_command_17s_decay"] = replay_command(
            ten_minute_file(folder, seconds=17.0, runs=1), 17.0
        )
        if args.part != "replay":
            for rate in (100, 400):
                share, samples, runs = cpu_share(rate, args.seconds, folder / f"r{rate}")
                print(f"record at {rate} Hz: CPU {share:.1%} of one core ({samples} samples, {runs} decays)")
                figures[f"record_{rate}hz"] = {
                    "cpu_pct_of_one_core": share * 100,
                    "samples": samples,
                    "decays": runs,
                    "mcap_mb_per_decay": mcap_mb(folder / f"r{rate}") / max(runs, 1),
                }
        started = time.perf_counter()
        path = ten_minute_file(folder)
        print(f"10-minute recording made in {time.perf_counter() - started:.1f} s (simulator at 40x)")
        figures["replay_in_process_600s"] = replay_in_process(path, 600.0, args.repeats)
    write_result(
        "record",
        "the recorder's CPU share against a real-time simulator in another process (release detection, MCAP, "
        "live refits, no viewer); replay of a 17 s decay by the command and of a 10-minute file in-process",
        counts={
            "cpu_share_wall_s": args.seconds if args.part != "replay" else 0,
            "replay_repeats": args.repeats,
        },
        figures=figures,
        baseline="BASELINE_SRC's tree (rows 'baseline'), same run"
        if os.environ.get("BASELINE_SRC")
        else None,
    )


if __name__ == "__main__":
    main()
