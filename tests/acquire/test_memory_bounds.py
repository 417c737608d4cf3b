"""What a recorder fed for a lab day keeps per decay (issue 22 item 8; the figure is bench_memory_day.py):
no predicted curve in a finished decay's outcome, only the newest outcomes kept, no list of every release
event in its detectors, no rerun recording (and its two threads) left behind by a view's finished run, the
C allocator's free pages given back once a decay has settled, and glibc's arenas capped for the record
daemon's threads."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tankdaq.acquire.decay import LiveFit
from tankdaq.acquire.events import KEPT_OUTCOMES, DecayOutcome, Event, Fitted, KeptOutcomes
from tankdaq.acquire.memory import ARENAS
from tankdaq.acquire.pipeline import DecayPipeline, DetectionSettings
from tankdaq.acquire.release import ReleaseDetector
from tankdaq.acquire.sinks import Sink
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import StreamBlock
from tankdaq.ident.signals import SAVGOL_CACHE, _savgol_weights, smoothed_derivatives
from tankdaq.live.identifier import OnlineResult
from tankdaq.records import DecayEnd
from tankdaq.samples import empty_samples
from tankdaq.viz.live import LiveView

TASKS = Path("/proc/self/task")

RUNS = 3


def _samples() -> np.ndarray:
    samples, _trace = hull_scenario(runs=RUNS, seed=5, rate_hz=100.0).samples()
    return samples


class FinalFits(Sink):
    """The last fit published in each decay, as the sinks saw it (curve included)."""

    def __init__(self) -> None:
        self.last: dict[int, OnlineResult] = {}

    def on_event(self, event: Event) -> None:
        if isinstance(event, Fitted):  # notes are not what this sink listens for
            self.last[event.run] = event.result


@pytest.mark.slow
def test_a_finished_decay_keeps_its_fit_without_the_curve_and_the_detector_no_event_list() -> None:
    samples = _samples()
    fits = FinalFits()
    pipeline = DecayPipeline(DetectionSettings(), [fits], fit=LiveFit(wait_for_fits=True))
    outcomes = []
    try:
        for i in range(0, samples.size, 20):  # 0.2 s reads at 100 Hz
            outcomes += pipeline.feed(StreamBlock(samples[i : i + 20], b"", 0.0))
    finally:
        pipeline.close()
    finished = [o for o in outcomes if o.ended.whole]
    assert len(finished) == RUNS
    for outcome in finished:
        assert outcome.fit is not None
        published = fits.last[outcome.run]
        assert published.predicted_t.size > 1000, "the sinks saw the whole curve"
        assert outcome.fit.predicted_t.size == 0 and outcome.fit.predicted_angle.size == 0
        assert outcome.fit.coefficients == published.coefficients
        assert outcome.fit.n_samples == published.n_samples
    assert all(detector.events_ == [] for detector in pipeline._detectors.values())
    assert list(pipeline.outcomes) == outcomes and pipeline.outcomes.count == len(outcomes)


def test_a_day_of_decays_keeps_the_newest_outcomes_and_counts_them_all() -> None:
    kept = KeptOutcomes()
    day = [
        DecayOutcome(run, "roll", None, None, 0.0, 8.0, DecayEnd.SETTLED, None, []) for run in range(1, 824)
    ]
    kept.extend(day[:-1])
    kept.append(day[-1])
    assert kept.count == 823
    assert list(kept) == day[-KEPT_OUTCOMES:] and len(kept) == KEPT_OUTCOMES


@pytest.mark.slow
def test_the_smoothing_weights_kept_are_bounded_over_many_windows() -> None:
    """Each decay's period sets its smoothing window: a day's windows must not pile up weight sets."""
    t = np.linspace(-1.0, 1.0, 4000)
    y = t**3 - 0.5 * t  # a cubic: the weights of order 3 give it back exactly
    for window in range(5, 5 + 2 * (SAVGOL_CACHE + 40), 2):
        value, _, _ = smoothed_derivatives(y, float(t[1] - t[0]), window, 3)
        assert np.allclose(value[window:-window], y[window:-window], rtol=0, atol=1e-9)
    assert _savgol_weights.cache_info().currsize <= SAVGOL_CACHE


@pytest.mark.slow
def test_a_detector_that_keeps_no_events_returns_the_same_ones() -> None:
    samples = _samples()
    offline = ReleaseDetector().fit(samples).events_
    live = ReleaseDetector(keep_events=False)
    returned = [event for i in range(0, samples.size, 37) for event in live.feed(samples[i : i + 37])]
    assert [e.kind for e in offline].count("released") == RUNS
    assert [(e.kind, e.index) for e in returned] == [(e.kind, e.index) for e in offline]
    assert live.events_ == []


def _rerun_threads() -> int:
    """Native threads of rerun recording streams in this process (each stream runs one of these); a thread
    that ends between the listing and the reading of its name is not counted."""
    count = 0
    for task in TASKS.iterdir():
        try:
            count += (task / "comm").read_text().strip() == "RecordingStream"
        except FileNotFoundError:
            continue
    return count


@pytest.mark.skipif(not TASKS.is_dir(), reason="counting native threads needs Linux's /proc/self/task")
@pytest.mark.slow
def test_a_saving_view_leaves_no_rerun_recording_behind_its_runs(tmp_path: Path) -> None:
    before = _rerun_threads()
    view = LiveView("save", on_note=lambda _line: None)
    samples = empty_samples(40)
    samples["t"] = np.arange(40) / 400.0
    for run in range(4):
        view.new_run(name=f"run {run}", rrd_path=tmp_path / f"run{run}.rrd", terms=("b1", "c1"))
        view.log_samples(samples)
        view.log_event("settled", "decay ended", 0.1)
        view.end_run()
    view.close(limit_s=600)  # bounded; every run's end is done on the view thread by then
    assert all((tmp_path / f"run{run}.rrd").stat().st_size > 0 for run in range(4))
    # at most the last run's, freed at the next run's end; rerun ends a dropped stream's thread on its
    # own, a moment later: waited for (a stream still running after 60 s is one left behind)
    deadline = time.monotonic() + 60.0
    while _rerun_threads() > before + 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _rerun_threads() <= before + 1


def _anonymous_kb() -> int:
    """This process's resident anonymous memory (kB): its heaps, not the libraries mapped from files."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("RssAnon:"):
            return int(line.split()[1])
    raise AssertionError("no RssAnon in /proc/self/status")


def _glibc() -> ctypes.CDLL | None:
    libc = ctypes.CDLL(None)
    return libc if hasattr(libc, "malloc_trim") and hasattr(libc, "gnu_get_libc_version") else None


@pytest.mark.skipif(
    not Path("/proc/self/status").is_file() or _glibc() is None,
    reason="glibc's arenas and Linux's /proc/self/status: what a settle gives back is glibc's to give",
)
@pytest.mark.slow
def test_a_settled_decay_gives_the_allocators_free_pages_back() -> None:
    """Measured on resident memory, which is unavoidable here (what is given back is pages the kernel
    takes), and made robust by size: 64 MB the C allocator holds free under a block still in use (where
    ``free`` never returns them by itself), against a pipeline's few MB of its own; no load changes it."""
    libc = _glibc()
    assert libc is not None
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    samples, _trace = hull_scenario(runs=1, seed=5, rate_hz=100.0).samples()
    pipeline = DecayPipeline(DetectionSettings(), [])  # release detection alone: the settle is what counts
    size, count = 64 * 1024, 1024  # below glibc's mmap threshold: in the main arena's heap
    blocks = [libc.malloc(size) for _ in range(count)]
    try:
        for block in blocks:
            ctypes.memset(block, 1, size)
        for block in blocks[:-1]:  # the last one stays: the free pages sit below a block in use
            libc.free(block)
        held_kb = _anonymous_kb()
        outcomes = [
            o
            for i in range(0, samples.size, 50)
            for o in pipeline.feed(StreamBlock(samples[i : i + 50], b"", 0.0))
        ]
        assert [o.ended for o in outcomes] == [DecayEnd.SETTLED]
        given_back_kb = held_kb - _anonymous_kb()
    finally:
        libc.free(blocks[-1])
    assert given_back_kb > 32 * 1024, f"{given_back_kb} kB given back after a settle"


ARENA_PROBE = """
import ctypes, sys, tempfile, threading
import numpy as np
from pathlib import Path
from tankdaq.acquire.memory import limit_arenas
if sys.argv[1] == "limit":
    limit_arenas()
ready, done = threading.Barrier(9), threading.Event()
def work():
    keep = np.ones(100_000)  # C malloc on this thread: it attaches to an arena
    ready.wait()
    done.wait()
threads = [threading.Thread(target=work) for _ in range(8)]
for thread in threads:
    thread.start()
ready.wait()  # eight threads hold memory at once: none can take an arena another let go
libc = ctypes.CDLL(None)
with tempfile.NamedTemporaryFile() as out:
    libc.fopen.restype = ctypes.c_void_p
    stream = ctypes.c_void_p(libc.fopen(out.name.encode(), b"w"))
    libc.malloc_info(0, stream)
    libc.fclose(stream)
    print(Path(out.name).read_text().count("<heap nr="))
done.set()
"""


@pytest.mark.skipif(_glibc() is None, reason="glibc's arenas: other C libraries have none to cap")
@pytest.mark.slow
def test_the_record_daemon_caps_glibcs_arenas() -> None:
    """Counted in a fresh process (a test process's arenas are already made): eight threads holding
    memory at once get at most the cap of arenas, where glibc alone gives them one each."""
    env = {k: v for k, v in os.environ.items() if k not in ("MALLOC_ARENA_MAX", "GLIBC_TUNABLES")}

    def arenas(mode: str) -> int:
        run = subprocess.run([sys.executable, "-c", ARENA_PROBE, mode], capture_output=True, text=True,
                             env=env, timeout=120, check=True)  # fmt: skip
        return int(run.stdout.strip())

    assert arenas("limit") <= ARENAS
    assert arenas("free") > ARENAS + 2  # what the cap prevents (one per thread on this machine)


MMAP_PROBE = """
import ctypes, sys
from tankdaq.acquire.memory import fix_mmap_threshold
if sys.argv[1] == "fixed":
    fix_mmap_threshold()
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
libc.free(libc.malloc(4 << 20))  # a large block freed: glibc alone raises its threshold past 4 MB
block = libc.malloc(1 << 20)
size_field = ctypes.c_size_t.from_address(block - ctypes.sizeof(ctypes.c_size_t)).value
print(bool(size_field & 2))  # the chunk's IS_MMAPPED bit: a mapping of its own, given back whole
libc.free(block)
"""


@pytest.mark.skipif(_glibc() is None, reason="glibc's mmap threshold: other C libraries have none")
@pytest.mark.slow
def test_large_blocks_keep_mappings_of_their_own_after_a_larger_one_was_freed() -> None:
    """In a fresh process: a 1 MB block after a 4 MB one was freed is still mapped on its own with the
    threshold fixed (given back whole when freed), where glibc alone cuts it from its heap."""
    env = {k: v for k, v in os.environ.items() if k not in ("MALLOC_MMAP_THRESHOLD_", "GLIBC_TUNABLES")}

    def mapped(mode: str) -> str:
        run = subprocess.run([sys.executable, "-c", MMAP_PROBE, mode], capture_output=True, text=True,
                             env=env, timeout=120, check=True)  # fmt: skip
        return run.stdout.strip()

    assert mapped("fixed") == "True"
    assert mapped("free") == "False"  # what the fixed threshold prevents


NUMPY_PROBE = """
import ctypes, sys, threading
import numpy as np
from tankdaq.acquire.memory import uncache_numpy_small_blocks
changed = uncache_numpy_small_blocks() if sys.argv[1] == "uncached" else False
class MallInfo2(ctypes.Structure):
    names = "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost"
    _fields_ = [(name, ctypes.c_size_t) for name in names.split()]
libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
made = []
def churn():  # seven buffers of every size numpy caches, made and freed on a thread of their own
    blocks = [np.ones(size, np.uint8) for size in range(1, 1024) for _ in range(7)]
    made.append(sum(block.nbytes for block in blocks))
before = libc.mallinfo2().uordblks
thread = threading.Thread(target=churn)
thread.start()
thread.join()
held = libc.mallinfo2().uordblks - before
grown = np.arange(10.0)
grown.resize(100_000, refcheck=False)  # realloc
works = bool(np.zeros(5000).sum() == 0 and grown[9] == 9 and grown[-1] == 0 and np.ones(3000).sum() == 3000)
print(changed, works, held, made[0])
"""


@pytest.mark.skipif(_glibc() is None, reason="glibc's mallinfo2 tells what is in use")
@pytest.mark.slow
def test_numpys_freed_small_buffers_go_back_to_malloc() -> None:
    """In fresh processes, on a thread as a recorder's reading and fitting threads: 7 buffers of every
    size under 1 kB (3.7 MB) made and freed. numpy's own cache keeps them in use; uncached, they are
    freed. ``-X dev`` (Python's debug hooks on its allocator) leaves numpy as it is. glibc's own
    per-thread cache (up to 7 freed chunks of each size under 1 kB, about 0.2 MB, counted as in use) is
    turned off in the probes, so that what is in use is what numpy holds."""
    env = {**os.environ, "GLIBC_TUNABLES": "glibc.malloc.tcache_count=0"}

    def probe(mode: str, *flags: str) -> tuple[str, str, int, int]:
        run = subprocess.run([sys.executable, *flags, "-c", NUMPY_PROBE, mode], capture_output=True,
                             text=True, env=env, timeout=120, check=True)  # fmt: skip
        changed, works, held, made = run.stdout.split()
        return changed, works, int(held), int(made)

    changed, works, held, made = probe("uncached")
    assert (changed, works) == ("True", "True")
    assert held < 0.02 * made, f"{held} of {made} bytes still in use once freed"
    changed, works, held, made = probe("numpy")
    assert (changed, works) == ("False", "True")
    assert held > 0.5 * made  # what uncaching prevents: numpy's cache keeps them
    assert probe("uncached", "-X", "dev")[:2] == ("False", "True")
