"""The longest gap between reads of the device while recording, from the host arrival stamps in the files.

The device is a simulated MTi-G in a process of its own, as hardware is: ``tankdaq simulate`` of this
tree (swath at T from 8 deg, 400 Hz at 460800 baud, sped up ``--sim-speed`` times) on its pty, and
``tankdaq record --port LINK --baud 460800 --rate 400 --viewer save --runs N`` opens it by path. The
recorder is this tree and, with ``--baseline-src`` (the ``src/`` of ``git archive COMMIT src``),
that code first, in the same run, each against a fresh simulator. Every MCAP keeps the host arrival
time of each raw chunk (one per read that brought bytes, ``store.reader.iter_raw_chunks``): the gaps
between consecutive chunks of a file are the gaps between reads, the pre-trigger, the release
confirmation and the settle included (the reads between decays are in no file). Reads are spaced
20 ms (``acquire.read_thread.READ_INTERVAL_S``), so a gap above that is a read that waited.

``--in-process-sim`` runs ``--port sim`` instead (the simulator a thread of the recorder). Reads that
bring no bytes are in no file, so a gap in a file is either a read that waited or a device that sent
nothing: a simulator starved of the interpreter (in-process) or of a CPU (a loaded machine) does that,
hardware does not. ``--device-realtime`` runs the simulator at SCHED_FIFO 1 (``chrt``, needs root),
as hardware that never waits for the host. Run as root, the recorders are run as a lab user without
CAP_SYS_NICE (``setpriv``): their reader process gets no real-time priority; ``--realtime-reader``
records with this tree once more as root, its reader process at the real-time priority it asks for.

Run: .venv/bin/python bench/bench_read_loop.py [--decays 50] [--sim-speed 8] [--baseline-src DIR]
     [--device-realtime] [--realtime-reader] [--in-process-sim] [--parallel]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from benchjson import write_result
from tankdaq.store.reader import iter_raw_chunks

#: ``tankdaq`` of whichever tankdaq PYTHONPATH gives (the venv's console script ignores it).
TANKDAQ = [sys.executable, "-c", "from tankdaq.cli import main; main()"]


SIM_BAUD = "460800"  # the slowest standard line for 400 Hz (``device.factory.sim_baud``)


def _env(src: str | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    if src:  # a git archive of src/ alone: the hulls come from this checkout
        env["PYTHONPATH"] = src
        env.setdefault("TANKDAQ_CONFIG_DIR", str(Path(__file__).resolve().parents[1] / "configs"))
    return env


@contextlib.contextmanager
def simulator(runs: int, speed: float, realtime: bool) -> Iterator[str]:
    """``tankdaq simulate`` of this tree in a process of its own for ``runs`` decays; yields its link.
    ``realtime``: at SCHED_FIFO 1 (``chrt``) once it answers, as hardware, which never waits for the
    host's CPUs."""
    args = ["simulate", "--hull", "swath", "--draft", "T", "--angle", "8", "--rate", "400"]
    args += ["--runs", str(runs), "--speed", f"{speed:g}", "--baud", SIM_BAUD]
    command = [*TANKDAQ, *args]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert process.stdout is not None
        link = process.stdout.readline().strip()
        if not link:
            raise SystemExit(f"the simulator did not start (exit code {process.wait()})")
        _wait_until_answering(link)
        if realtime:  # only now: computing the scenario at SCHED_FIFO would take a CPU from everyone
            subprocess.run(["chrt", "--all-tasks", "--fifo", "--pid", "1", str(process.pid)], check=True)
        yield link
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _wait_until_answering(link: str, attempts: int = 10) -> None:
    """``tankdaq device info`` until the simulator answers. Powered up and not acknowledged, it measures at
    its default 100 Hz, and computes the scenario at that rate first: 17 s for 52 runs on this machine,
    during which it answers nothing (a record started then gives up). Left in Config, it answers at once."""
    for _ in range(attempts):
        info = subprocess.run([*TANKDAQ, "device", "info", link], capture_output=True, timeout=120)
        if info.returncode == 0:
            return
    raise SystemExit(f"the simulator on {link} never answered GoToConfig")


@dataclass(frozen=True)
class Setup:
    """How every recording of the run is made (``--help``)."""

    decays: int
    speed: float
    in_process: bool
    device_realtime: bool


#: A recorder run as a lab user: without CAP_SYS_NICE its reader process gets no real-time priority.
AS_A_USER = ["setpriv", "--bounding-set=-sys_nice", "--inh-caps=-sys_nice"] if os.geteuid() == 0 else []


def record(src: str | None, out: Path, setup: Setup, as_user: bool) -> float:
    """One ``tankdaq record`` of ``decays`` decays at 400 Hz with the view saving; its wall time."""
    decays, speed = setup.decays, setup.speed
    args = ["record", "--hull", "swath", "--draft", "T", "--angle", "8", "--rate", "400"]
    args += ["--runs", str(decays), "--viewer", "save", "--out", str(out)]
    with contextlib.ExitStack() as stack:
        if setup.in_process:
            args += ["--port", "sim", "--sim-speed", f"{speed:g}"]
        else:  # runs to spare: the device clock runs from power-up, while it computes and before the record
            link = stack.enter_context(simulator(decays + 20, speed, setup.device_realtime))
            args += ["--port", link, "--baud", SIM_BAUD]
        command = [*(AS_A_USER if as_user else []), *TANKDAQ, *args]
        started = time.monotonic()
        done = subprocess.run(command, capture_output=True, text=True, env=_env(src), timeout=7200)
        wall_s = time.monotonic() - started
    if done.returncode:  # say why; the files it closed are measured all the same
        print(f"record exited {done.returncode}: {done.stderr.strip().splitlines()[-3:]}")
    return wall_s


def read_gaps_ms(out: Path) -> list[np.ndarray]:
    """Per decay file: the gaps (ms) between consecutive reads, from the raw chunks' host stamps."""
    gaps = []
    for path in sorted(out.glob("*.mcap")):
        host_ns = np.array([t for t, _raw in iter_raw_chunks(path)], dtype=np.int64)
        gaps.append(np.diff(host_ns) / 1e6)
    return gaps


def gap_figures(gaps: list[np.ndarray], wall_s: float) -> dict[str, float]:
    """The gaps between reads over every decay file of one recorder run."""
    if not gaps:
        return {"decay_files": 0}
    every = np.concatenate(gaps)
    return {
        "decay_files": len(gaps),
        "reads": every.size,
        "wall_s": wall_s,
        "gap_median_ms": np.median(every),
        "gap_p99_ms": np.percentile(every, 99),
        "gap_longest_ms": every.max(),
        "reads_over_50ms": (every > 50).sum(),
        "longest_per_decay_median_ms": np.median([g.max() for g in gaps]),
    }


def describe(tree: str, f: dict[str, float]) -> str:
    if not f["decay_files"]:
        return f"{tree}: no decay file"
    return (
        f"{tree}: {f['decay_files']} decay files, {f['reads']} reads, {f['wall_s']:.0f} s wall; gap "
        f"between reads median {f['gap_median_ms']:.1f} ms, 99th percentile {f['gap_p99_ms']:.1f} ms, "
        f"longest {f['gap_longest_ms']:.0f} ms; reads over 50 ms {f['reads_over_50ms']}; "
        f"longest per decay median {f['longest_per_decay_median_ms']:.0f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--decays", type=int, default=50)
    parser.add_argument("--sim-speed", type=float, default=8.0)
    parser.add_argument("--baseline-src", default=None)
    parser.add_argument("--in-process-sim", action="store_true", help="--port sim: the simulator a thread")
    parser.add_argument("--device-realtime", action="store_true", help="the simulator at SCHED_FIFO 1 (chrt)")
    parser.add_argument(
        "--realtime-reader", action="store_true", help="this tree once more, its reader allowed SCHED_FIFO"
    )
    parser.add_argument("--parallel", action="store_true", help="all recordings at once, each its simulator")
    args = parser.parse_args()
    setup = Setup(args.decays, args.sim_speed, args.in_process_sim, args.device_realtime)
    print(f"{platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    where = "a thread of the recorder" if setup.in_process else "a process of its own"
    where += ", at SCHED_FIFO 1" if setup.device_realtime else ""
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, simulator {where}, x{setup.speed:g}")
    print(f"recorders as a user without CAP_SYS_NICE: {' '.join(AS_A_USER) or '(not root: as they are)'}")
    print("recordings " + ("at once" if args.parallel else "one after the other"))
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    this = os.environ.get("PYTHONPATH")
    runs: list[tuple[str, str | None, bool]] = [("this tree", this, True)]
    if args.baseline_src:
        runs.insert(0, (f"baseline {args.baseline_src}", args.baseline_src, True))
    if args.realtime_reader:
        runs.append(("this tree, reader allowed SCHED_FIFO", this, False))
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(len(runs) if args.parallel else 1) as pool:
        outs = [Path(tmp) / str(i) for i in range(len(runs))]
        walls = pool.map(lambda i: record(runs[i][1], outs[i], setup, runs[i][2]), range(len(runs)))
        figures = {}
        for (label, _src, _as_user), out, wall_s in zip(runs, outs, walls, strict=True):
            figures[label] = gap_figures(read_gaps_ms(out), wall_s)
            print(describe(label, figures[label]), flush=True)
    write_result(
        "read_loop",
        "the gaps between reads of the device while `tankdaq record` records at 400 Hz with the view saving "
        "(simulated MTi-G sped up), from the host arrival stamps in the files",
        counts=asdict(setup) | {"parallel": args.parallel},
        figures=figures,
        baseline=f"--baseline-src {args.baseline_src} (row 'baseline'), same run"
        if args.baseline_src
        else None,
    )
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
