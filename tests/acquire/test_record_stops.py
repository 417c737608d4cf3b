"""A recording stopped mid-decay, end to end from the simulated MTi-G on a real pty: unplugged (the file
closes, the next decay records), killed with kill -9 (every flushed chunk survives), sent SIGTERM (the file
is finished). Split from test_record.py so that the two spread over the test workers.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from acquire.test_record import _events, _tankdaq, record_args
from support.event_stream import wait_for_event
from support.record_settings import sim_record_settings
from support.run_metadata import run_metadata
from support.web_browser import children
from tankdaq.acquire.daemon import RecordDaemon
from tankdaq.acquire.events import DeviceBack, DeviceLost, Event, Fitted
from tankdaq.acquire.listeners import EventLog
from tankdaq.device.simulator import OWNER_FILE, TEMP_PREFIX
from tankdaq.records import DecayEnd
from tankdaq.store.reader import read_recording


@pytest.mark.slow
def test_unplug_mid_decay_closes_the_file_and_the_next_decay_records(tmp_path: Path) -> None:
    settings = sim_record_settings(tmp_path, runs=2, sim_speed=4.0, sim_seed=5, reconnect_timeout_s=30.0)
    plugged = threading.Event()
    daemon: RecordDaemon

    def on_event(event: Event) -> None:
        """Unplugged mid-decay (once the first decay's first live fit is out: its samples are in), plugged
        back once the recorder has said the device is lost: the events, not the test's clock."""
        if isinstance(event, Fitted) and event.run == 1 and not plugged.is_set():
            plugged.set()
            threading.Thread(target=daemon.simulator.unplug, daemon=True).start()
        elif isinstance(event, DeviceLost):
            threading.Thread(target=daemon.simulator.replug, daemon=True).start()

    heard = EventLog(on_event)
    daemon = RecordDaemon(settings, sinks=[heard])
    outcomes = daemon.run()
    assert plugged.is_set()
    assert len(heard.of(DeviceLost)) == 1 and len(heard.of(DeviceBack)) == 1
    assert len(outcomes) == 2
    cut, whole = outcomes
    assert cut.ended is DecayEnd.DEVICE_LOST
    partial = read_recording(cut.path)
    assert _events(partial, "unplug") and partial.samples.size > 50
    assert partial.ended is DecayEnd.DEVICE_LOST and run_metadata(cut.path)["ended"] == "device_lost"
    with cut.path.open("rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) > 0
    complete = read_recording(whole.path)
    assert whole.ended.whole and complete.ended is whole.ended
    assert _events(complete, "release") and _events(complete, "settled")


def _recording_after_release(out: Path, *extra: str) -> subprocess.Popen:
    """``tankdaq record --port sim`` in a subprocess, returned once it has reported a release."""
    args = record_args("sim", out, "--viewer", "none", "--events", "jsonl")
    proc = _tankdaq(*args, *extra)
    wait_for_event(proc, "released", 60.0)
    return proc


def _cmdline(pid: int) -> bytes:
    """The command line of process ``pid`` (b"" once it has ended)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def _chunk_spans(path: Path) -> list[tuple[int, int]]:
    """(first, last) log time of every complete chunk of a killed file, in file order (ns)."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    from tankdaq.store.record_scan import MCAP_DAMAGE

    spans: list[tuple[int, int]] = []
    with path.open("rb") as f:
        try:
            for record in StreamReader(f, emit_chunks=True).records:
                if isinstance(record, Chunk) and record.message_start_time:
                    spans.append((record.message_start_time, record.message_end_time))
        except MCAP_DAMAGE:  # the killed tail, cut anywhere (even inside a record's length)
            pass
    return spans


def _release_log_time(path: Path) -> int | None:
    """The log time of the release event in a growing or killed file's complete chunks (ns), None before."""
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    from tankdaq.store.record_scan import MCAP_DAMAGE

    events: set[int] = set()
    with path.open("rb") as f:
        try:
            for record in StreamReader(f).records:
                if isinstance(record, Channel) and record.topic == "/events":
                    events.add(record.id)
                elif (
                    isinstance(record, Message)
                    and record.channel_id in events
                    and json.loads(record.data)["kind"] == "release"
                ):
                    return record.log_time
        except MCAP_DAMAGE:
            pass
    return None


def _decay_chunks(path: Path) -> list[tuple[int, int]]:
    """The complete chunks of the decay: those that start at or after its release (the chunks before hold
    the pre-trigger history, written at once at the release); none before the release is in the file."""
    release = _release_log_time(path)
    return [] if release is None else [s for s in _chunk_spans(path) if s[0] >= release]


@pytest.mark.slow
def test_kill_9_mid_decay_loses_at_most_the_last_second(tmp_path: Path) -> None:
    """kill -9 in the middle of a decay: every flushed chunk survives and no chunk holds over 1 s; the
    simulated MTi-G's process, left at the end of its socket, stops and removes its pty folder.

    The loss is measured in the file, not against the test's clock: each complete chunk is one
    flush, so its span of log times is the most a kill can cost, whatever the machine's load.
    """
    proc = _recording_after_release(tmp_path, "--runs", "1", "--sim-seed", "2")
    (path,) = tmp_path.glob("*.mcap")
    (device,) = [c for c in children(proc.pid) if b"tankdaq.device.simulator.process" in _cmdline(c)]
    device_ended = os.pidfd_open(device)
    try:
        deadline = time.monotonic() + 60
        while len(_decay_chunks(path)) < 3 and time.monotonic() < deadline:  # three flushes of the decay
            time.sleep(0.02)  # polling the file, a real condition with a bound
        assert len(_decay_chunks(path)) >= 3, "the recording did not grow during the decay"
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    try:
        assert select.select([device_ended], [], [], 30.0)[0], "the simulated MTi-G outlived its recorder"
    finally:
        os.close(device_ended)
    owners = [folder / OWNER_FILE for folder in Path(tempfile.gettempdir()).glob(f"{TEMP_PREFIX}*")]
    assert not [f for f in owners if f.is_file() and f.read_text().strip() == str(device)]
    spans = _chunk_spans(path)
    assert read_recording(path).ended is DecayEnd.CUT
    result = subprocess.run(
        [str(Path(sys.executable).with_name("tankdaq")), "recover", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode in (0, 3), result.stderr
    recovered = next(tmp_path.glob("*.recovered.mcap"))
    with recovered.open("rb") as f:
        reader = make_reader(f)
        newest = max(m.log_time for _, c, m in reader.iter_messages(log_time_order=False))
        samples = sum(1 for _ in reader.iter_messages(topics=["/samples"]))
        events = {
            json.loads(m.data)["kind"]: m.log_time for *_, m in reader.iter_messages(topics=["/events"])
        }
    assert "release" in events and samples > 0
    assert (
        read_recording(recovered).ended is DecayEnd.RECOVERED
        and run_metadata(recovered)["ended"] == "recovered"
    )
    assert newest >= max(last for _, last in spans), "a flushed message was lost"
    decay = _decay_chunks(path)
    assert len(decay) >= 3 and all(first >= events["release"] for first, _ in decay)
    longest_s = max(last - first for first, last in decay) / 1e9
    assert longest_s <= 1.0, f"a flush held {longest_s:.2f} s of data"


@pytest.mark.slow  # a record subprocess up to a live fit: 21 s measured under load 18
def test_sigterm_closes_the_file_properly(tmp_path: Path) -> None:
    proc = _recording_after_release(tmp_path, "--sim-speed", "4")
    wait_for_event(proc, "fitted", 60.0)  # mid-decay: a live fit of it is out
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=30)
    assert proc.returncode == 130  # as Ctrl-C (docs/recording-format.md)
    path = next(tmp_path.glob("*.mcap"))
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()  # a seeking reader needs the footer: the file was finished
    assert summary is not None and summary.statistics.message_count > 0
    assert read_recording(path).ended is DecayEnd.STOPPED
