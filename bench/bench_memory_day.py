"""Memory over a lab day: the record pipeline's RSS over 8 simulated hours at 400 Hz, time-compressed.

In the loop is what ``tankdaq record --port sim --rate 400 --viewer save`` runs once the device is open:
``RecordDaemon.run`` (``cli.record.run_record`` without its terminal status line) with its reading thread
(``acquire.read_thread``) calling the driver's ``read_block`` (the real decoder, link counters and packet
counter tracker), the daemon's ``_feed``, the decay pipeline and its real sinks: the online identifier
(``--model``; record's default is ``auto``) with its refits on its worker thread and the final fit, one
MCAP per decay, the view saving an .rrd beside each, and the run catalogue (a SQLite file, written on its
own thread), plus one probe sink that reads ``VmRSS`` from ``/proc/self/status`` at each decay's settle,
and adds the resident sets of the processes it started (the view's, ``viz.view_process``).

Not in the loop: the pty, pyserial and the hand-shake (``open_device``), and the simulator's firmware
thread, which encodes frame by frame in Python and cannot play 400 Hz much faster than real time on this
machine. Instead the driver reads a ``CompressedLine``: the simulator's decays (swath roll at T from
8 deg, 35 s each: 10 s still, tilt and hold, 25 s of decay; ``CHUNK_RUNS`` runs scripted once by the
simulator's physics and sensor model and played again and again, the clock carried on) as the MTData2
bytes of an MTi-G-710's decay outputs, made by ``xsens.synthetic``'s array encoder. The device clock runs
up to ``--speed`` times the wall clock and never more than ``CompressedLine.LEAD_S`` ahead of what the
pipeline has been fed, so nothing piles up in the reading thread's queue however loaded the machine is.

Each tree runs in a child process of its own, side by side (``--baseline-src``: the ``src/`` of ``git
archive COMMIT src`` on PYTHONPATH, as bench_read_loop.py does). ``--tracemalloc`` starts tracemalloc
at the end of the warm-up (``--warmup`` decays; much slower from there) and prints what grew between two
decays after it and the last one, by traceback; ``--type-growth`` the objects by type that grew between
the same two decays (cheap: no tracing). At each release (the last decay's view work done by then) the
probe prints where the memory is (``memory_state``: anonymous mappings by kind, glibc's ``mallinfo2`` in
use and free, its arenas, Python's allocated blocks, the threads), and the report fits a slope to each
part (``--rss-only``: RSS alone, the probe's own reading of smaps and glibc's state left out).
``--catalogue off`` leaves the catalogue's sink out; ``--malloc-trim`` has the probe trim glibc's
heap at each settle (what the pipeline itself now does: ``acquire.memory``).

Run: .venv/bin/python bench/bench_memory_day.py [--hours 8] [--baseline-hours 2] [--baseline-src DIR]
"""

from __future__ import annotations

import argparse
import collections
import ctypes
import dataclasses
import gc
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import psutil

from benchjson import write_result
from memory_day_report import describe, figures, read_rows

if TYPE_CHECKING:
    from tankdaq.physics.scenario import DecayScenario

#: Runs scripted once and played again and again (about 140 k samples at 400 Hz).
CHUNK_RUNS = 10
#: The decays before the warm-up ends (kernels loaded, caches and pools filled); ``--warmup``.
WARMUP_DECAYS = 30
RATE_HZ = 400.0
#: Frames of each traceback tracemalloc keeps (more is slower).
TRACE_FRAMES = 12
#: The device the bytes come from (its SampleTimeFine wraps at one day).
PRODUCT = "MTi-G-710-2A8G4"


class RepeatedScenario:
    """The simulated decays by sample index: ``CHUNK_RUNS`` runs of the scenario scripted once (by the
    simulator's own physics and sensor model) and played again and again, the device clock
    (SampleTimeFine) and the packet counter carried on from one round to the next."""

    def __init__(self, scenario: DecayScenario) -> None:
        self.scenario = dataclasses.replace(scenario, runs=CHUNK_RUNS)
        self.chunk, _trace = self.scenario.samples()
        self.rate_hz = float(self.scenario.rate_hz)
        self.origin_s = float(self.chunk["t"][0])

    def block(self, start: int, stop: int) -> np.ndarray:
        """Samples ``start`` .. ``stop - 1``."""
        index = np.arange(start, stop)
        rounds, row = np.divmod(index, self.chunk.size)
        block = self.chunk[row]  # a copy
        ticks_per_round = round(self.chunk.size / self.rate_hz * 10_000)  # SampleTimeFine: 10 kHz
        block["ticks"] += rounds * ticks_per_round
        block["t"] = block["ticks"] / 10_000
        block["counter"] = (block["counter"] + rounds * self.chunk.size) & 0xFFFF
        return block


def own_rss_kb() -> int:
    """This process's resident set size (kB), from /proc/self/status."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError("no VmRSS in /proc/self/status")


def children_rss_kb() -> int:
    """The resident set size (kB) of every process this one started and that still runs: the view's
    process (``viz.view_process``) and multiprocessing's resource tracker beside it."""
    total = 0
    for child in psutil.Process().children(recursive=True):
        try:
            total += child.memory_info().rss // 1024
        except psutil.Error:
            continue  # a view process that ended between the listing and the reading
    return total


def rss_kb() -> int:
    """What the recorder holds (kB): its own resident set and its children's."""
    return own_rss_kb() + children_rss_kb()


class MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (2.33+): what its arenas hold, in bytes."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
                     "fordblks", "keepcost")
    ]  # fmt: skip


def glibc() -> ctypes.CDLL | None:
    """The C library when it is glibc with ``mallinfo2`` (else None: another libc, another platform)."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = MallInfo2
        libc.fopen.restype = ctypes.c_void_p
        libc.fopen.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
        libc.fclose.argtypes = [ctypes.c_void_p]
        libc.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
    except (OSError, AttributeError):
        return None
    return libc


def arena_count(libc: ctypes.CDLL) -> int:
    """glibc's malloc arenas (``malloc_info``'s ``<heap nr=...>`` elements)."""
    with tempfile.NamedTemporaryFile() as out:
        stream = libc.fopen(out.name.encode(), b"w")
        libc.malloc_info(0, stream)
        libc.fclose(stream)
        return Path(out.name).read_text().count("<heap nr=")


def anonymous_kb() -> dict[str, int]:
    """Resident anonymous memory (kB) by the kind of mapping it is in, told apart by the mapping's size:
    ``heap_kb`` glibc's main arena; ``pyarena_kb`` 1 MB mappings (Python's object arenas); ``stack_kb``
    8 MB (thread stacks); ``mapped_kb`` other mappings up to 64 MB (glibc's thread arenas, large numpy
    buffers); ``reserved_kb`` beyond 64 MB (mimalloc's arenas: rerun's Rust allocator)."""
    totals = dict.fromkeys(("heap_kb", "pyarena_kb", "stack_kb", "mapped_kb", "reserved_kb"), 0)
    kind = ""
    for line in Path("/proc/self/smaps").read_text().splitlines():
        head = line.split()
        if "-" in head[0] and len(head) >= 5:  # a mapping's first line: range perms offset dev inode [path]
            path = head[5] if len(head) > 5 else ""
            start, end = (int(x, 16) for x in head[0].split("-"))
            kind = "heap_kb" if path == "[heap]" else "" if path else size_kind((end - start) // 1024)
        elif head[0] == "Rss:" and kind:
            totals[kind] += int(head[1])
    return totals


def size_kind(size_kb: int) -> str:
    """The bucket of an anonymous mapping of this size (``anonymous_kb``)."""
    if size_kb == 1024:
        return "pyarena_kb"
    if size_kb == 8192:
        return "stack_kb"
    return "mapped_kb" if size_kb <= 65536 else "reserved_kb"


def rss_parts() -> dict[str, int]:
    """RSS (kB): this process's and its children's (the view's process), and their sum."""
    own, children = own_rss_kb(), children_rss_kb()
    return {"rss_kb": own + children, "own_rss_kb": own, "children_rss_kb": children}


def memory_state(libc: ctypes.CDLL | None) -> dict[str, int]:
    """Where the memory is (kB): RSS (this process's and its children's: the view's process), this
    process's anonymous memory by mapping, what glibc's arenas hold in use and free, the Python blocks
    allocated, the threads."""
    state = {**rss_parts(), **anonymous_kb(), "py_blocks": sys.getallocatedblocks()}
    state["threads"] = len(os.listdir("/proc/self/task"))
    if libc is not None:
        info = libc.mallinfo2()
        state |= {
            "malloc_used_kb": (info.uordblks + info.hblkhd) // 1024,
            "malloc_free_kb": info.fordblks // 1024,
        }
        state["malloc_arenas"] = arena_count(libc)
    return state


def top_growth(before: tracemalloc.Snapshot, after: tracemalloc.Snapshot, limit: int = 15) -> list[str]:
    """What grew most between two snapshots, grouped by the allocation's traceback (innermost tankdaq
    frame first), as lines."""
    lines = []
    for stat in after.compare_to(before, "traceback")[:limit]:
        frames = [f for f in stat.traceback if "tankdaq" in f.filename] or list(stat.traceback)
        where = " <- ".join(f"{Path(f.filename).name}:{f.lineno}" for f in reversed(frames[-4:]))
        lines.append(f"{stat.size_diff / 1024:+9.0f} kB {stat.count_diff:+7d} blocks  {where}")
    return lines


class CompressedLine:
    """What a bench ``MTiDriver`` reads instead of a serial port: the simulated decays as MTData2 bytes
    (the decay outputs an MTi-G-710 sends, made by ``xsens.synthetic``'s array encoder), the device
    clock running ``speed`` times the wall clock but never more than ``LEAD_S`` of device time ahead of
    what the pipeline has been fed (so the reading thread's queue stays short whatever the load)."""

    LEAD_S = 2.0

    def __init__(self, samples: RepeatedScenario, speed: float) -> None:
        self.samples = samples
        self.speed = speed
        self.sent = 0  # samples sent so far
        self.fed_s = 0.0  # device seconds the pipeline has been fed (the daemon's ``_feed`` sets it)
        self.origin_s = samples.origin_s
        self._started = time.monotonic()

    def read(self) -> bytes:
        from unittest import mock

        from tankdaq.xsens import synthetic
        from tankdaq.xsens.timebase import MODULUS_ONE_DAY

        rate = self.samples.rate_hz
        due_s = min((time.monotonic() - self._started) * self.speed, self.fed_s + self.LEAD_S)
        due = max(self.sent, int(due_s * rate))
        if due == self.sent:
            return b""
        block = self.samples.block(self.sent, due)
        self.sent = due
        signals = {
            "PacketCounter": block["counter"],
            "SampleTimeFine": block["ticks"] % MODULUS_ONE_DAY,
            "EulerAngles": np.degrees(np.column_stack([block["roll"], block["pitch"], block["yaw"]])),
            "RateOfTurn": np.column_stack([block["p"], block["q"], block["r"]]),
            "Acceleration": np.column_stack([block["ax"], block["ay"], block["az"]]),
            "StatusWord": block["status"],
        }
        # decay_capture's encoder, given these signals (the same bytes on every tree measured)
        with mock.patch.object(synthetic, "decay_signals", lambda *_args: signals):
            return synthetic.decay_capture(block.size, rate)


def probe_sink(args: argparse.Namespace, out: Path, snapshots: dict[str, tracemalloc.Snapshot]) -> object:
    """The bench's listener of the pipeline (``RssProbe``), last after the real sinks."""
    from tankdaq.acquire.sinks import Sink

    counts: dict[int, collections.Counter[str]] = {}
    started = time.monotonic()
    libc = glibc()
    lines = (out / "events.txt").open("w")

    class RssProbe(Sink):
        """RSS at each settle; where the memory is (``memory_state``) at each release, the last decay's
        view work done by then; the tracemalloc snapshots at the warm-up's end and the last decay;
        ``--malloc-trim``: glibc's ``malloc_trim(0)`` after each settle's measure (a probe of what
        the allocator keeps free)."""

        def on_release(self, decay: object, pretrigger: object) -> None:
            run = decay.run  # type: ignore[attr-defined]
            state = rss_parts() if args.rss_only else memory_state(libc)
            print(json.dumps({"before_decay": run, **state}), flush=True)
            if args.type_growth and run in (args.warmup + 2, args.decays):
                counts[run] = collections.Counter(type(o).__qualname__ for o in gc.get_objects())
                if len(counts) == 2:
                    first, last = counts.values()
                    grown = (last - first).most_common(12)
                    print(
                        json.dumps({"object_growth": grown, "decays": args.decays - args.warmup - 2}),
                        flush=True,
                    )

        def on_settle(self, decay: object) -> None:
            run = decay.run  # type: ignore[attr-defined]
            if args.tracemalloc and run == args.warmup:  # traced from here: the warm-up runs at full speed
                tracemalloc.start(TRACE_FRAMES)
            if args.tracemalloc and run in (args.warmup + 2, args.decays):
                snapshots["from" if run < args.decays else "to"] = tracemalloc.take_snapshot()
            wall_s = round(time.monotonic() - started, 1)
            print(json.dumps({"decay": run, "rss_kb": rss_kb(), "wall_s": wall_s}), flush=True)
            if args.malloc_trim and libc is not None:
                libc.malloc_trim(0)

        def on_event(self, event: object) -> None:
            print(event.line(), file=lines, flush=True)  # type: ignore[attr-defined]

    return RssProbe()


def child(args: argparse.Namespace) -> None:
    """One recording of ``args.decays`` decays in this process; one JSON line per decay on stdout."""
    from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
    from tankdaq.acquire.recorder import Recorder
    from tankdaq.catalogue.hooks import CatalogueSink, CatalogueWriter
    from tankdaq.device.driver import MTiDriver
    from tankdaq.device.factory import OpenDevice

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    snapshots: dict[str, tracemalloc.Snapshot] = {}
    probe = probe_sink(args, out, snapshots)

    class BenchDriver(MTiDriver):
        """The real driver's reading and decoding (``read_block``) over a ``CompressedLine``."""

        def __init__(self, line: CompressedLine) -> None:
            # the line waits for the pipeline
            super().__init__("bench", rate_hz=RATE_HZ, silence_timeout_s=3600.0)
            self.line = line
            self._reset_stream_state(None, PRODUCT)
            self._last_data = time.monotonic()

        def _read(self) -> bytes:
            return self.line.read()

    class BenchRecorder(Recorder):
        """``record``'s recorder with the bench driver in place of ``open_device``; the rest is its own."""

        def _open_device(self) -> MTiDriver:
            scenario = self.simulation_scenario()
            self.line = CompressedLine(RepeatedScenario(scenario), args.speed)
            driver = BenchDriver(self.line)
            self.device = OpenDevice(driver)
            return driver

        def _feed(self, pipeline: object, read: object) -> None:
            samples = read.block.samples  # type: ignore[attr-defined]
            if samples.size:
                self.line.fed_s = float(samples["t"][-1]) - self.line.origin_s
            super()._feed(pipeline, read)  # type: ignore[arg-type]

    settings = RecordSettings(
        port="sim", hull="swath", draft=1.0, angle_deg=8.0, rate_hz=RATE_HZ, out_dir=out / "recordings",
        runs=args.decays, viewer=args.viewer, model=args.model,
    )  # fmt: skip
    print(json.dumps({"decay": 0, "rss_kb": rss_kb(), "wall_s": 0.0}), flush=True)
    catalogue = str(out / "catalogue.sqlite") if args.catalogue == "on" else "none"
    with CatalogueWriter.from_option(catalogue, lambda line: None) as writer:
        sinks = [CatalogueSink(writer)] if writer.enabled else []
        daemon = RecordDaemon(settings, sinks=[*sinks, probe], recorder=BenchRecorder)  # type: ignore[list-item]
        daemon.run()
    status = daemon.status
    summary = {"decays": daemon.outcomes.count, "samples": status.samples, "gaps": status.gaps}
    summary |= {"bad_frames": status.bad_frames, "rss_kb_closed": rss_kb()}
    print(json.dumps(summary), flush=True)
    if len(snapshots) == 2:
        grown = top_growth(snapshots["from"], snapshots["to"])
        print(json.dumps({"tracemalloc": grown}), flush=True)


def start_tree(
    src: str | None, args: argparse.Namespace, decays: int, out: Path, log: Path
) -> subprocess.Popen:
    """The child on the tree at ``src`` (None: this one), its JSON lines into ``log`` as they come."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    if src:  # a git archive of src/ alone: the hulls come from this checkout
        env["PYTHONPATH"] = src
        env.setdefault("TANKDAQ_CONFIG_DIR", str(Path(__file__).resolve().parents[1] / "configs"))
    command = [sys.executable, __file__, "--child", "--decays", str(decays), "--speed", f"{args.speed:g}"]
    command += ["--viewer", args.viewer, "--out", str(out), "--warmup", str(args.warmup)]
    command += ["--model", args.model, "--catalogue", args.catalogue]
    command += ["--type-growth"] if args.type_growth else []
    command += ["--rss-only"] if args.rss_only else []
    command += (["--tracemalloc"] if args.tracemalloc else []) + (
        ["--malloc-trim"] if args.malloc_trim else []
    )
    with log.open("w") as sink:
        return subprocess.Popen(command, stdout=sink, stderr=subprocess.STDOUT, env=env)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=8.0, help="simulated hours of this tree")
    parser.add_argument("--baseline-hours", type=float, default=2.0, help="simulated hours of the baseline")
    parser.add_argument("--speed", type=float, default=60.0, help="the device clock's speed-up at most")
    parser.add_argument("--viewer", default="save", choices=("save", "none"))
    parser.add_argument("--model", default="auto", help="the live model (record's default: auto)")
    parser.add_argument("--report", nargs="*", default=None, help="describe these logs (a run cut short)")
    parser.add_argument("--baseline-src", default=None)
    parser.add_argument("--log-dir", default=None, help="keep each tree's per-decay JSON lines here")
    parser.add_argument("--tracemalloc", action="store_true")
    parser.add_argument("--catalogue", default="on", choices=("on", "off"), help="the run catalogue's sink")
    parser.add_argument("--type-growth", action="store_true", help="objects by type, warm-up vs last decay")
    parser.add_argument(
        "--malloc-trim", action="store_true", help="the probe trims glibc's heap at each settle"
    )
    parser.add_argument(
        "--rss-only", action="store_true", help="at each release RSS alone (no smaps, mallinfo, arenas)"
    )
    parser.add_argument("--warmup", type=int, default=WARMUP_DECAYS, help="decays before the warm-up ends")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--decays", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--out", default="", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return
    run_s = 35.0  # the scenario's run: release_after_s + decay_s
    if args.report is not None:
        for log in args.report:
            print("\n".join(describe(log, read_rows(Path(log)), args.warmup, run_s)))
        return
    print(f"{platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    trees: list[tuple[str, str | None, float]] = [("this tree", os.environ.get("PYTHONPATH"), args.hours)]
    if args.baseline_src:
        trees.insert(0, (f"baseline {args.baseline_src}", args.baseline_src, args.baseline_hours))
    with tempfile.TemporaryDirectory() as tmp:
        logs = Path(args.log_dir or tmp)
        logs.mkdir(parents=True, exist_ok=True)
        children, results = [], {}
        for i, (tree, src, hours) in enumerate(trees):  # side by side: the same load for both
            decays = max(args.warmup + 3, round(hours * 3600 / run_s))
            print(f"{tree}: {decays} decays at {RATE_HZ:g} Hz ({decays * run_s / 3600:.2f} simulated h)")
            log = logs / f"memory-day-{i}.jsonl"
            children.append((tree, log, start_tree(src, args, decays, Path(tmp) / str(i), log)))
        for tree, log, child_process in children:
            if child_process.wait():
                print(f"{tree}: child exited {child_process.returncode}; see {log}")
            for line in describe(tree, read_rows(log), args.warmup, run_s):
                print(line, flush=True)
            results[tree] = figures(read_rows(log), args.warmup, run_s)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    write_result(
        "memory_day",
        "RSS of the record pipeline (400 Hz, time-compressed) at each decay's settle",
        counts={"rate_hz": RATE_HZ, "warmup_decays": args.warmup, "viewer": args.viewer},
        figures=results,
    )


if __name__ == "__main__":
    main()
