"""Signals never cost a decay (issue 19): Ctrl-C, SIGTERM and SIGHUP (a closed terminal or SSH session)
close the open decay as a complete file, ``record`` exits 130 and its summary counts the files that
exist; a recorder whose live refit runs away still hears Ctrl-C.

Real processes: ``tankdaq record --port sim`` (the simulated MTi-G on a pty) and, for the runaway,
``tests/runaway_recorder.py`` (the real daemon whose live identifier is given a gyro 1000x too large).
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

from event_stream import events_of, wait_for_event

TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))
RUNAWAY = Path(__file__).with_name("runaway_recorder.py")
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


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGHUP])  # SIGTERM: test_record.py
def test_a_signal_mid_decay_closes_a_complete_file_exits_130_and_the_summary_counts_it(
    tmp_path: Path, signum: signal.Signals
) -> None:
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8"]
    args += ["--viewer", "none", "--sim-speed", "4", "--out", str(tmp_path), "--events", "jsonl"]
    proc = subprocess.Popen([TANKDAQ, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_event(proc, "released", START_S)
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
    assert settled["settle_reason"] == "note" and settled["path"] == str(path)
    events = _complete(path)
    assert events[0]["kind"] == "release" and events[-1]["kind"] == "settled"
    files = list(tmp_path.glob("*.mcap"))
    counted = re.search(r"(\d+) decay\(s\) recorded", err)
    assert counted is not None and int(counted.group(1)) == len(files) == 1, err


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
