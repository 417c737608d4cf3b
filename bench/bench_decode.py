"""Protocol decoding speed: batch and streaming decoders against the per-message Python parser.

Run: ``.venv/bin/python bench/bench_decode.py``. One core (the process is pinned to one CPU).
Captures: (a) 1 million decay frames (PacketCounter, SampleTimeFine, EulerAngles, RateOfTurn,
Acceleration, StatusWord, float32: 69 bytes each), generated with array code; (b) the real
einride-1 capture (100 frames, 6 layouts incl. GNSS PVT messages) repeated to 1 million frames.
Streaming is fed in 4 KiB chunks.
``--frames N`` sets the count (run_all's quick mode: 100 000).
Best of several runs; CPU time is the figure (the machine is shared).

Confirmation cost (``bench_decode.py confirmation`` runs only this part): the decoders as they were
before the framer confirmed frames (the ``tankdaq`` tree of commit ``BASELINE``, extracted with
``git archive`` and imported under another name) against the current ones, in the same run, on the
clean decay capture, the mixed einride capture and a noisy one (3 % of frames with a corrupted byte,
stray ``FA FF 36`` headers in 3 %); streaming on the first tenth of each. Before and after run in
turn (best of each), so a change of load during the run affects both alike.
"""

from __future__ import annotations

import argparse
import importlib
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

from benchjson import write_result
from tankdaq.xsens.column_decoder import decode_capture
from tankdaq.xsens.framer import StreamFramer
from tankdaq.xsens.mtdata2 import decode_mtdata2
from tankdaq.xsens.stream_decoder import StreamDecoder
from tankdaq.xsens.synthetic import decay_capture, noisy_capture

FRAMES = 1_000_000
#: The last commit before the framer confirmed frames (issue 9).
BASELINE = "9a26490"
REPO = Path(__file__).resolve().parents[1]
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


def alternately(
    old: Callable[[], int], new: Callable[[], int], repeats: int
) -> tuple[float, float, int, int]:
    """(best CPU s of ``old``, of ``new``, their frame counts), the two run in turn: a change of load on
    the shared machine during the measurement then hits both sides alike."""
    before, after, n_old, n_new = float("inf"), float("inf"), 0, 0
    for _ in range(repeats):
        cpu, _, n_old = timed(old, 1)
        before = min(before, cpu)
        cpu, _, n_new = timed(new, 1)
        after = min(after, cpu)
    return before, after, n_old, n_new


def batch(data: bytes) -> int:
    return decode_capture(data).n_messages


def streaming(data: bytes) -> int:
    return _stream(StreamDecoder(), data)


def per_message(data: bytes) -> int:
    return sum(1 for frame in StreamFramer().feed(data) for _ in [decode_mtdata2(frame.payload)])


def report(label: str, data: bytes) -> dict[str, float]:
    """M frames/s of CPU time of each decoder on one capture."""
    figures = {}
    for name, run, repeats, part in (
        ("batch", batch, 5, data),
        ("streaming 4 KiB", streaming, 3, data),
        ("per-message Python", per_message, 2, data[: len(data) // 10]),
    ):
        cpu, wall, frames = timed(lambda run=run, part=part: run(part), repeats)
        print(f"{label:27s} {name:19s} {frames / cpu / 1e6:6.2f} M frames/s CPU "
              f"({frames / wall / 1e6:.2f} wall; {frames} frames, {cpu:.3f} s CPU)", flush=True)  # fmt: skip
        figures[f"{name.split()[0]}_m_frames_per_s_cpu"] = frames / cpu / 1e6
    return figures


def baseline_package(folder: Path) -> ModuleType:
    """``tankdaq`` as of ``BASELINE``, importable as ``tankdaq_baseline`` (its imports are relative)."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", BASELINE, "src/tankdaq"], check=True,
                             capture_output=True).stdout  # fmt: skip
    with tarfile.open(fileobj=__import__("io").BytesIO(archive)) as tar:
        tar.extractall(folder, filter="data")
    (folder / "src" / "tankdaq").rename(folder / "tankdaq_baseline")
    sys.path.insert(0, str(folder))
    return importlib.import_module("tankdaq_baseline")


def confirmation_cost(captures: dict[str, bytes]) -> dict[str, dict[str, float]]:
    """Batch and streaming throughput before and after the confirmation step, same run, same captures."""
    ratios: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as folder:
        baseline_package(Path(folder))
        old_batch = importlib.import_module("tankdaq_baseline.xsens.batch")
        old_stream = importlib.import_module("tankdaq_baseline.xsens.stream")
        for label, data in captures.items():
            for name, old, new, repeats, part in (
                ("batch", lambda d: old_batch.decode_capture(d).n_messages, batch, 5, data),
                ("streaming 4 KiB", lambda d: _stream(old_stream.StreamDecoder(), d), streaming, 3,
                 data[: len(data) // 10]),
            ):  # fmt: skip
                before, after, n_old, n_new = alternately(
                    lambda old=old, part=part: old(part), lambda new=new, part=part: new(part), repeats
                )
                print(f"{label:27s} {name:16s} before {n_old / before / 1e6:6.2f} M/s ({n_old} msgs), "
                      f"after {n_new / after / 1e6:6.2f} M/s ({n_new} msgs): cost {after / before - 1:+.1%} "
                      "CPU time", flush=True)  # fmt: skip
                ratios.setdefault(label, {})[f"{name.split()[0]}_cpu_after_over_before"] = after / before
    return ratios


def _stream(decoder: StreamDecoder, data: bytes) -> int:
    return sum(decoder.feed(data[i : i + CHUNK]).n_messages for i in range(0, len(data), CHUNK))


def main() -> None:
    """All figures; ``bench_decode.py confirmation`` measures only the confirmation cost."""
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", nargs="?", choices=("confirmation",))
    parser.add_argument("--frames", type=int, default=FRAMES)
    args = parser.parse_args()
    only_confirmation, frames = args.part == "confirmation", args.frames
    decay = decay_capture(frames)
    captures = {"decay, 69-byte frames": decay, "noisy decay (3 %/3 %)": noisy_capture(frames)[0]}
    figures: dict[str, dict[str, float]] = {}
    if not only_confirmation:
        figures["decay"] = report("decay, 69-byte frames", decay)
    if EINRIDE.is_file():
        captures["einride-1 (mixed)"] = EINRIDE.read_bytes() * (frames // 100)
        if not only_confirmation:
            figures["einride_mixed"] = report("einride-1 (mixed)", captures["einride-1 (mixed)"])
    else:
        print(f"einride-1 not found at {EINRIDE}: mixed-capture figures skipped")
    ratios = confirmation_cost(captures)
    write_result(
        "decode" if not only_confirmation else "decode_confirmation",
        "MTData2 decoding throughput on one pinned core (CPU time, best of several): batch, streaming in "
        "4 KiB "
        "chunks, per-message Python; and the frame confirmation's cost against the decoders before it",
        counts={"frames": frames, "chunk_bytes": CHUNK, "einride": EINRIDE.is_file()},
        figures=figures,
        ratios=ratios,
        baseline=f"the decoders of commit {BASELINE} (before frame confirmation), same run, run in turn",
    )


if __name__ == "__main__":
    main()
