"""The reader process: a stop drains what it has not read yet, a vanished port is ``gone``, and a recorder
that dies takes the process with it (no orphan).

Real pseudo-terminals (``os.openpty``, raw like the simulator's) and real processes; every wait is a
bounded loop on a condition.
"""

from __future__ import annotations

import fcntl
import os
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
import tty
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from functools import partial

import pytest

from tankdaq.device.read_process import NO_DATA, ReadProcess

WAIT_S = 30.0


def _until(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"waited {WAIT_S:g} s for {what}"
        time.sleep(0.005)


@contextmanager
def _pty() -> Iterator[tuple[int, int]]:
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        yield master, slave
    finally:
        for fd in (master, slave):
            with suppress(OSError):
                os.close(fd)


def _waiting(fd: int) -> int:
    """Bytes the tty holds unread."""
    return int(struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0])


def _ended(pid: int) -> bool:
    """True once ``pid`` is gone or a zombie (its parent died; nobody reaped it yet)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def test_a_stop_gives_every_byte_that_arrived_before_it_even_unread_by_then() -> None:
    """The process reads once, then sleeps 60 s; what arrives meanwhile comes out after the stop."""
    with _pty() as (master, slave), ReadProcess(slave, interval_s=60.0, wait_s=0.01) as process:
        first = b"\xfa\xff" * 500
        os.write(master, first)
        chunks = process.chunks(threading.Event())
        got = b""
        while len(got) < len(first):  # the first read (or reads, if it woke before all arrived)
            got += next(chunks).data
        later = bytes(range(256)) * 8  # within the tty's 4 KiB read buffer
        os.write(master, later)
        _until(lambda: _waiting(slave) == len(later), "the bytes to wait in the tty")
        stop = threading.Event()
        stop.set()
        rest = list(process.chunks(stop))
        assert got + b"".join(chunk.data for chunk in rest) == first + later
        assert all(chunk.gone is None for chunk in rest)
        stamps = [chunk.host_t for chunk in rest]
        assert stamps == sorted(stamps) and rest[-1].monotonic_s <= time.monotonic()
    assert process.exit_note() == "exit code 0"


def test_a_port_that_vanishes_is_gone_with_the_reason_and_the_process_ends() -> None:
    with _pty() as (master, slave), ReadProcess(slave, interval_s=0.01, wait_s=0.01) as process:
        os.write(master, b"abc")
        os.close(master)  # the other end of the cable goes: the tty reads EIO
        chunks = list(process.chunks(threading.Event()))
        assert b"".join(chunk.data for chunk in chunks) in (b"", b"abc")  # a hang-up may drop what is unread
        reason = chunks[-1].gone  # EIO, or (Linux's pty) readable with nothing: pyserial's words
        assert reason is not None and ("Errno 5" in reason or reason == NO_DATA)
        _until(lambda: process.exit_note() != "running", "the reader process to end")


RECORDER = """
import os, sys
from tankdaq.device.read_process import NO_DATA, ReadProcess
master, slave = os.openpty()
process = ReadProcess(slave, 0.02, 0.01)
print(process.pid, flush=True)
sys.stdin.readline()
os.kill(os.getpid(), int(sys.argv[1]))
"""


@pytest.mark.slow
def test_a_recorder_that_dies_takes_its_reader_process_with_it() -> None:
    """Killed hard (SIGKILL: no clean-up ran) or by Ctrl-C, the recorder leaves no reader process behind."""
    for signum in (signal.SIGKILL, signal.SIGINT):
        recorder = subprocess.Popen(
            [sys.executable, "-c", RECORDER, str(int(signum))],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert recorder.stdout is not None and recorder.stdin is not None
            pid = int(recorder.stdout.readline())
            assert not _ended(pid), "the reader process runs while its recorder does"
            recorder.stdin.write("die\n")
            recorder.stdin.flush()
            recorder.wait(timeout=WAIT_S)
            _until(partial(_ended, pid), f"the reader process to end after {signum.name}")
        finally:
            recorder.kill()
            recorder.wait()


def test_a_reader_process_killed_ends_its_chunks_without_a_stop() -> None:
    """Killed from outside (the OOM killer, a stray kill), the process's chunks end and ``stopping`` is still
    False: the driver then takes the device for gone and reconnects (a new reader process)."""
    with _pty() as (master, slave), ReadProcess(slave, interval_s=0.01, wait_s=0.01) as process:
        os.write(master, b"\xfa" * 10)
        os.kill(process.pid, signal.SIGKILL)
        list(process.chunks(threading.Event()))
        assert not process.stopping
        killed = f"exit code {-signal.SIGKILL}"
        _until(lambda: process.exit_note() == killed, "the exit code of a killed process")
