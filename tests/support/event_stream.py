"""Steering a ``tankdaq record`` subprocess by its event stream (``--events jsonl`` on stdout), never by
the lines it prints for people."""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable
from typing import Any


def wait_for_event(proc: subprocess.Popen[str], kind: str, timeout_s: float, **values: Any) -> list[dict]:
    """The events ``proc`` wrote up to the first ``kind`` event holding ``values``; the process is killed
    (and the test fails) when it ends or ``timeout_s`` passes first."""
    return wait_until(proc, lambda event: all(event.get(k) == v for k, v in values.items()), kind, timeout_s)


def wait_until(
    proc: subprocess.Popen[str], holds: Callable[[dict], bool], kind: str, timeout_s: float
) -> list[dict]:
    """The events ``proc`` wrote up to the first ``kind`` event for which ``holds`` is true; the process is
    killed (and the test fails) when it ends or ``timeout_s`` passes first."""
    assert proc.stdout is not None
    events: list[dict] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                break
            continue
        event = json.loads(line)
        events.append(event)
        if event["event"] == kind and holds(event):
            return events
    proc.kill()
    proc.communicate(timeout=60)
    raise AssertionError(f"no such {kind} event within {timeout_s:g} s: {events}")


def events_of(stdout: str, kind: str) -> list[dict]:
    """The ``kind`` events in a finished command's stdout (``--events jsonl``)."""
    return [event for event in map(json.loads, stdout.splitlines()) if event["event"] == kind]
