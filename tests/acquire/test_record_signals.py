"""Signals never cost a decay (issue 19): Ctrl-C, SIGTERM and SIGHUP (a closed terminal or SSH session)
close the open decay as a complete file, ``record`` exits 130 and its summary counts the files that
exist; the file says the decay was stopped (issue 37: partial, never taken for a whole decay); a recorder
whose live refit runs away still hears Ctrl-C.

Real processes: ``tankdaq record --port sim`` (the simulated MTi-G on a pty) and, for the runaway,
``tests/support/runaway_recorder.py`` (the real daemon whose live identifier is given a gyro 1000x too large).
Files are read back with the official ``mcap`` reader, which needs the footer and summary. Every
process started here is stopped here.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from support.event_stream import events_of, wait_for_event, wait_until
from support.run_metadata import run_metadata
from tankdaq.acquire.replay import replay_recording
from tankdaq.records import DecayEnd
from tankdaq.store.reader import read_recording

TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))
RUNAWAY = Path(__file__).resolve().parents[1] / "support/runaway_recorder.py"
#: Generous bounds on a loaded machine: conditions decide, these only stop a hung test.
START_S = 120.0
STOP_S = 60.0


def _wait_for_line(proc: subprocess.Popen[str], wanted: str) -> list[str]:
    """The runaway recorder's own stdout lines up to ``wanted`` (the process is killed past START_S)."""
    assert proc.stdout is not None
    lines: list[str] = []
    deadline = time.monotonic() + START_S
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line and proc.poll() is not None:
            break
        lines.append(line)
        if line.split() == wanted.split():
            return lines
    proc.kill()
    proc.communicate(timeout=STOP_S)
    raise AssertionError(f"no {wanted!r} within {START_S:g} s: {lines}")


def _complete(path: Path) -> list[dict]:
    """The file's events, read through its summary (a file without footer raises here)."""
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count > 0
        return [json.loads(m.data) for *_, m in reader.iter_messages(topics=["/events"])]


#: Device seconds of the decay recorded when the test stops it: the lab's case, stopped 3 s after the release.
STOPPED_AFTER_S = 3.0


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGHUP])  # SIGTERM: test_record_stops.py
@pytest.mark.slow
def test_a_signal_mid_decay_closes_a_complete_file_that_says_it_was_stopped(
    tmp_path: Path, signum: signal.Signals
) -> None:
    """Stopped once 3 s of the decay are recorded (the live fits' ends say how far the file has got, in device
    time): a complete file, exit 130, the summary counts it; the file, its line and ``identify`` say the
    decay was stopped by the operator and is partial (issue 37: it was catalogued complete)."""
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8"]
    args += ["--viewer", "none", "--sim-speed", "2", "--out", str(tmp_path), "--events", "jsonl"]
    proc = subprocess.Popen([TANKDAQ, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        *_, released = wait_for_event(proc, "released", START_S)
        recorded = released["t_s"] + STOPPED_AFTER_S
        wait_until(proc, lambda fit: fit["t_end_s"] >= recorded, "fitted", START_S)
        (path,) = tmp_path.glob("*.mcap")
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=STOP_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert [event["signal"] for event in events_of(out, "stopping")] == [signum.name]
    (settled,) = events_of(out, "settled")
    assert (settled["ended"], settled["whole"], settled["path"]) == ("stopped", False, str(path))
    after_s = settled["ended_after_s"]
    assert after_s >= STOPPED_AFTER_S
    assert (
        f"run 1: stopped by the operator {after_s:.1f} s after the release: partial, left out of campaigns"
        in err
    )
    events = _complete(path)
    assert events[0]["kind"] == "release" and events[-1]["kind"] == "settled"
    assert events[-1]["data"] == {"ended": "stopped"}
    assert run_metadata(path)["ended"] == "stopped"
    assert read_recording(path).ended is DecayEnd.STOPPED
    files = list(tmp_path.glob("*.mcap"))
    counted = re.search(r"(\d+) decay\(s\) recorded", err)
    assert counted is not None and int(counted.group(1)) == len(files) == 1, err
    if signum is signal.SIGINT:  # a fit of the file says it covers part of the decay
        identify = [TANKDAQ, "identify", str(path), "--json"]
        fitted = subprocess.run(identify, capture_output=True, text=True, timeout=START_S)
        assert fitted.returncode == 0, fitted.stderr
        (warning,) = [
            line for line in json.loads(fitted.stdout)["warnings"] if "stopped by the operator" in line
        ]
        assert f"{path.stem}: stopped by the operator {after_s:.1f} s after the release: partial" in warning
        (replayed,) = replay_recording(path, speed=None, viewer="none")  # the file ends mid-decay
        assert replayed.ended is DecayEnd.STREAM_ENDED
        assert replayed.last_t == read_recording(path).samples["t"][-1]  # to the file's last sample
        assert replayed.ended_after_s == pytest.approx(after_s, abs=0.011)  # the release within one sample


@pytest.mark.slow
def test_ctrl_c_is_heard_while_a_live_refit_runs_away_and_the_file_closes_complete(tmp_path: Path) -> None:
    """Heard while the refit still runs (the kernels release the lock); a second Ctrl-C while the file
    closes (the final fit waits up to 5 s on the runaway) does not cut it."""
    args = [sys.executable, str(RUNAWAY), str(tmp_path)]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_line(proc, "refit started")
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        heard_lines = _wait_for_line(proc, "stop event SIGINT")
        proc.send_signal(signal.SIGINT)  # impatient: a second Ctrl-C while the file closes
        out, err = proc.communicate(timeout=STOP_S)
        out = "".join(heard_lines) + out
        exited = time.monotonic()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    heard = re.search(r"heard (\S+) refit running (\w+)", out)
    assert heard is not None, out
    assert heard.group(2) == "True", "the signal was heard while the runaway refit was running"
    print(f"heard after {float(heard.group(1)) - sent:.3f} s, exited after {exited - sent:.2f} s")
    (path,) = tmp_path.glob("*.mcap")
    events = _complete(path)
    assert events[-1]["kind"] == "settled"
    assert "files 1" in out
