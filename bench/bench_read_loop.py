"""The longest gap between reads of the device while recording, from the host arrival stamps in the files.

``tankdaq record --port sim --rate 400 --viewer save --runs N`` (the built-in simulated MTi-G on
its pty, swath at T from 8 deg, sped up ``--sim-speed`` times) of this tree and,
with ``--baseline-src`` (the ``src/`` of ``git archive COMMIT src``), of that code in turn in the
same run. Every MCAP keeps the host arrival time of each raw chunk (one per read,
``store.reader.iter_raw_chunks``): the gaps between consecutive chunks of a file are the gaps
between reads, the pre-trigger, the release confirmation and the settle included (the reads
between decays are in no file). Reads are spaced 20 ms (``acquire.read_thread.READ_INTERVAL_S``),
so a gap above that is a read that waited.

Run: .venv/bin/python bench/bench_read_loop.py [--decays 50] [--sim-speed 8] [--baseline-src DIR]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tankdaq.store.reader import iter_raw_chunks

#: ``tankdaq`` of whichever tankdaq PYTHONPATH gives (the venv's console script ignores it).
TANKDAQ = [sys.executable, "-c", "from tankdaq.cli import main; main()"]


def record(src: str | None, out: Path, decays: int, speed: float) -> float:
    """One ``tankdaq record --port sim`` of ``decays`` decays at 400 Hz with the view saving; its wall
    time. The simulated MTi-G serves its pty from a thread of the recorder's process: it competes for
    the interpreter with the reading thread, which a real device does not."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    if src:  # a git archive of src/ alone: the hulls come from this checkout
        env["PYTHONPATH"] = src
        env.setdefault("TANKDAQ_CONFIG_DIR", str(Path(__file__).resolve().parents[1] / "configs"))
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8", "--rate", "400"]
    args += ["--runs", str(decays), "--sim-speed", f"{speed:g}", "--viewer", "save", "--out", str(out)]
    started = time.monotonic()
    done = subprocess.run([*TANKDAQ, *args], capture_output=True, text=True, env=env, timeout=3600)
    if done.returncode:  # say why; the files it closed are measured all the same
        print(f"record exited {done.returncode}: {done.stderr.strip().splitlines()[-3:]}")
    return time.monotonic() - started


def read_gaps_ms(out: Path) -> list[np.ndarray]:
    """Per decay file: the gaps (ms) between consecutive reads, from the raw chunks' host stamps."""
    gaps = []
    for path in sorted(out.glob("*.mcap")):
        host_ns = np.array([t for t, _raw in iter_raw_chunks(path)], dtype=np.int64)
        gaps.append(np.diff(host_ns) / 1e6)
    return gaps


def describe(tree: str, gaps: list[np.ndarray], wall_s: float) -> str:
    if not gaps:
        return f"{tree}: no decay file"
    every = np.concatenate(gaps)
    worst = np.array([g.max() for g in gaps])
    return (
        f"{tree}: {len(gaps)} decay files, {every.size} reads, {wall_s:.0f} s wall; gap between reads "
        f"median {np.median(every):.1f} ms, 99th percentile {np.percentile(every, 99):.1f} ms, "
        f"longest {every.max():.0f} ms; reads over 50 ms {int((every > 50).sum())}; "
        f"longest per decay median {np.median(worst):.0f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--decays", type=int, default=50)
    parser.add_argument("--sim-speed", type=float, default=8.0)
    parser.add_argument("--baseline-src", default=None)
    args = parser.parse_args()
    print(f"{platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    trees: list[tuple[str, str | None]] = [("this tree", os.environ.get("PYTHONPATH"))]
    if args.baseline_src:
        trees.insert(0, (f"baseline {args.baseline_src}", args.baseline_src))
    with tempfile.TemporaryDirectory() as tmp:
        for i, (tree, src) in enumerate(trees):
            out = Path(tmp) / str(i)
            wall_s = record(src, out, args.decays, args.sim_speed)
            print(describe(tree, read_gaps_ms(out), wall_s), flush=True)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
