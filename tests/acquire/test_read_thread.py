"""The reads of the device happen in a process that does nothing else, the blocks are decoded on a thread
that does nothing else, and a stop loses no block read.

All real: the simulated MTi-G on a pty opened through pyserial, the reader process on its descriptor,
the daemon's own pipeline and files, read back with the official ``mcap`` reader. The spies below call
the real methods and only note which thread (or process) called them.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path

import pytest

from support.record_settings import sim_record_settings
from tankdaq.acquire.daemon import RecordDaemon
from tankdaq.acquire.decay import LiveDecay
from tankdaq.acquire.events import Event, Fitted
from tankdaq.acquire.read_thread import THREAD_NAME
from tankdaq.acquire.release import ReleaseDetector
from tankdaq.acquire.sinks import Sink
from tankdaq.device.driver import MTiDriver, StreamBlock
from tankdaq.device.read_process import Chunk, ReadProcess
from tankdaq.records import DecayEnd
from tankdaq.store.reader import iter_raw_chunks, read_recording
from tankdaq.store.writer import RecordingWriter

#: One decay at 8x, a fixed seed.
_settings = partial(sim_record_settings, runs=1, sim_speed=8.0, sim_seed=5)


class _Reads:
    """Every block the driver made of a read, the threads that made them (the real ``_block_of``), and
    the reader processes with every chunk they sent (the real ``ReadProcess``)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.blocks: list[StreamBlock] = []
        self.threads: set[threading.Thread] = set()
        self.processes: list[ReadProcess] = []
        self.chunks: list[Chunk] = []
        self.more = threading.Condition()
        real_block_of, real_init, real_chunks = MTiDriver._block_of, ReadProcess.__init__, ReadProcess.chunks

        def block_of(driver: MTiDriver, raw: bytes, host_t: float, now: float) -> StreamBlock:
            block = real_block_of(driver, raw, host_t, now)
            with self.more:
                self.blocks.append(block)
                self.threads.add(threading.current_thread())
                self.more.notify_all()
            return block

        def init(process: ReadProcess, *args: object) -> None:
            real_init(process, *args)  # type: ignore[arg-type]
            self.processes.append(process)

        def chunks(process: ReadProcess, *args: object) -> Iterator[Chunk]:
            for chunk in real_chunks(process, *args):  # type: ignore[arg-type]
                self.chunks.append(chunk)
                yield chunk

        monkeypatch.setattr(MTiDriver, "_block_of", block_of)
        monkeypatch.setattr(ReadProcess, "__init__", init)
        monkeypatch.setattr(ReadProcess, "chunks", chunks)


Seen = dict[str, set[threading.Thread]]


def _spy(monkeypatch: pytest.MonkeyPatch, owner: type, name: str, seen: Seen) -> None:
    real: Callable[..., object] = getattr(owner, name)

    def call(*args: object, **kwargs: object) -> object:
        seen.setdefault(f"{owner.__name__}.{name}", set()).add(threading.current_thread())
        return real(*args, **kwargs)

    monkeypatch.setattr(owner, name, call)


class _ThreadSink(Sink):
    """A listener of the pipeline that notes the thread of every call it hears."""

    def __init__(self, seen: Seen) -> None:
        self.seen = seen

    def _note(self, what: str) -> None:
        self.seen.setdefault(f"sink.{what}", set()).add(threading.current_thread())

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> None:
        self._note("on_block")

    def on_release(self, decay: LiveDecay, pretrigger: object) -> None:
        self._note("on_release")

    def on_event(self, event: Event) -> None:
        if isinstance(event, Fitted):
            self._note("on_event(Fitted)")

    def on_settle(self, decay: LiveDecay) -> None:
        self._note("on_settle")


@pytest.mark.slow
def test_no_release_detection_fit_or_write_runs_on_the_reading_thread(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    reads = _Reads(monkeypatch)
    seen: Seen = {}
    _spy(monkeypatch, ReleaseDetector, "feed", seen)
    for name in ("write_raw", "write_samples", "write_event", "write_fit"):
        _spy(monkeypatch, RecordingWriter, name, seen)
    (outcome,) = RecordDaemon(_settings(tmp_path), sinks=[_ThreadSink(seen)]).run()
    assert outcome.ended.whole and outcome.path is not None
    assert reads.threads and {thread.name for thread in reads.threads} == {THREAD_NAME}
    # the reads were made by a process of their own, which has ended; the file's stamps are its reads'
    assert reads.processes
    assert all(p.pid != os.getpid() and p.exit_note() != "running" for p in reads.processes)
    stamps = {int(chunk.host_t * 1e9) for chunk in reads.chunks}
    in_file = [host_ns for host_ns, raw in iter_raw_chunks(outcome.path) if raw]
    assert in_file and set(in_file) <= stamps
    wanted = {"ReleaseDetector.feed", "RecordingWriter.write_raw", "RecordingWriter.write_fit"}
    wanted |= {"sink.on_block", "sink.on_release", "sink.on_event(Fitted)", "sink.on_settle"}
    assert wanted <= set(seen), sorted(seen)
    for what, threads in seen.items():
        assert not threads & reads.threads, f"{what} ran on the reading thread"


@pytest.mark.slow
def test_a_stop_mid_decay_feeds_every_block_already_read_into_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``stop()`` mid-decay while the pipeline is held until the reader has read 10 blocks more: those
    blocks (and any read after) are in the decay's file, which closes complete."""
    reads = _Reads(monkeypatch)
    daemon: RecordDaemon
    held: list[bool] = []

    class StopMidDecay(Sink):
        def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> None:
            if decay is None or held or block.samples.size == 0:
                return
            if float(block.samples["t"][-1]) - decay.release_t < 3.0:
                return
            daemon.stop()
            with reads.more:
                target = len(reads.blocks) + 10
                held.append(reads.more.wait_for(lambda: len(reads.blocks) >= target, timeout=30.0))

    daemon = RecordDaemon(_settings(tmp_path, runs=None), sinks=[StopMidDecay()])
    (outcome,) = daemon.run()
    assert held == [True], "the reader went on reading while the pipeline was held"
    assert outcome.ended is DecayEnd.STOPPED and outcome.path is not None
    assert not read_recording(outcome.path).truncated
    in_file = [host_ns for host_ns, raw in iter_raw_chunks(outcome.path) if raw]
    read = [int(block.host_t * 1e9) for block in reads.blocks if block.raw]
    after_start = [host_ns for host_ns in read if host_ns >= in_file[0]]
    assert len(after_start) > 10
    assert after_start == in_file, "every block read up to the stop reached the file, in order"
