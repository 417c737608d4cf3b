"""Protocol decoding speed: batch and streaming decoders against the per-message Python parser.

Run: ``.venv/bin/python bench/bench_decode.py``. One core (the process is pinned to one CPU).
Captures: (a) 1 million decay frames (PacketCounter, SampleTimeFine, EulerAngles, RateOfTurn,
Acceleration, StatusWord, float32: 69 bytes each), generated with array code; (b) the real
einride-1 capture (100 frames, 6 layouts incl. GNSS PVT messages) repeated to 1 million frames.
Streaming is fed in 4 KiB chunks. Best of several runs; CPU time is the figure (the machine is shared).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

from tankdaq.xsens.batch import decode_capture
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import decode_mtdata2
from tankdaq.xsens.stream import StreamDecoder
from tankdaq.xsens.synthetic import decay_capture

FRAMES = 1_000_000
CHUNK = 4096
EINRIDE = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "xsens-captures" / "einride-1" / "output.bin"
)


def timed(run: Callable[[], int], repeats: int) -> tuple[float, float, int]:
    """(best CPU s, best wall s, frames) over ``repeats`` runs.

    The machine is shared: CPU time of this (single-threaded, pinned) process is the figure; wall
    time beside it shows what the load added.
    """
    cpu, wall, count = [], [], 0
    for _ in range(repeats):
        start_cpu, start_wall = time.process_time(), time.perf_counter()
        count = run()
        cpu.append(time.process_time() - start_cpu)
        wall.append(time.perf_counter() - start_wall)
    return min(cpu), min(wall), count


def batch(data: bytes) -> int:
    return decode_capture(data).n_messages


def streaming(data: bytes) -> int:
    decoder = StreamDecoder()
    return sum(decoder.feed(data[i : i + CHUNK]).n_messages for i in range(0, len(data), CHUNK))


def per_message(data: bytes) -> int:
    return sum(1 for frame in StreamFramer().feed(data) for _ in [decode_mtdata2(frame.payload)])


def report(label: str, data: bytes) -> None:
    for name, run, repeats, part in (
        ("batch", batch, 5, data),
        ("streaming 4 KiB", streaming, 3, data),
        ("per-message Python", per_message, 2, data[: len(data) // 10]),
    ):
        cpu, wall, frames = timed(lambda run=run, part=part: run(part), repeats)
        print(f"{label:27s} {name:19s} {frames / cpu / 1e6:6.2f} M frames/s CPU "
              f"({frames / wall / 1e6:.2f} wall; {frames} frames, {cpu:.3f} s CPU)", flush=True)  # fmt: skip


def main() -> None:
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    decay = decay_capture(FRAMES)
    report("decay, 69-byte frames", decay)
    if EINRIDE.is_file():
        report("einride-1 x 10000 (mixed)", EINRIDE.read_bytes() * (FRAMES // 100))
    else:
        print(f"einride-1 not found at {EINRIDE}: mixed-capture figures skipped")


if __name__ == "__main__":
    main()
