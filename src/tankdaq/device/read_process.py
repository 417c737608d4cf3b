"""The reads of a streaming device, in a process of their own that does nothing else.

A thread of the recorder shares the interpreter with the pipeline, the live fit, the view and the
files: on a busy host its reads wait for them, and the bytes sit that long in the port's buffers
(``bench/bench_read_loop.py`` measures the wait). ``ReadProcess`` runs this
file as a small Python process (``python -I -S``: the standard library only, nothing of tankdaq,
no site packages) on the serial port's file descriptor, inherited. Every ``interval_s`` it reads
what has arrived, stamps the host arrival time (wall and monotonic clock) and sends (stamps, bytes)
down a pipe; the driver decodes them in the recorder. Commands still go from the driver: the process
lives only while the device streams.

It asks for the lowest real-time priority (``REALTIME_PRIORITY``) and reads at the normal one
where that is not allowed. Stopping (``stop``, or the recorder's end of the control pipe closing),
the process reads once more what has arrived, sends it and ends: nothing read is lost. It ignores
the terminal's signals (a session of its own): the recorder decides when reading ends, and its
death closes the control pipe, which ends the process (no orphan). A read that fails or finds the
port closed is sent as ``gone`` with the reason, and the process ends.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import select
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

#: One message from the process: kind (DATA or GONE), wall-clock and monotonic stamps (s), length.
HEADER = struct.Struct("<BddI")
DATA, GONE = 0, 1
#: The pipe to the recorder holds this much (Linux's default limit for a user); a full pipe makes
#: the process wait, as the reading thread's queue did: some 30 s of 400 Hz output.
PIPE_BYTES = 1 << 20
#: How long ``close`` waits for the process to end before it is killed.
END_WAIT_S = 5.0
#: pyserial's words for a port that is readable but gives nothing (the pty or cable is gone).
NO_DATA = (
    "device reports readiness to read but returned no data (device disconnected or multiple access on port?)"
)
CONTROL, OUT = 0, 1  # the process's stdin (stop, or EOF) and stdout (the messages)
#: The real-time priority the process asks for (SCHED_FIFO, the lowest level): it sleeps between reads
#: and reads a few kB, so on a busy host it is the one process that should not wait for a CPU. Granted to
#: root, to CAP_SYS_NICE or under an rtprio limit (docs/protocol.md); otherwise it reads at the normal one.
REALTIME_PRIORITY = 1


@dataclass(frozen=True)
class Chunk:
    """One read of the process: the bytes and when they arrived; ``gone``: why the port failed."""

    data: bytes
    host_t: float  # time.time() just after the read
    monotonic_s: float  # time.monotonic() just after it (one clock for every process of the host)
    gone: str | None = None


class ReadProcess:
    """The process reading file descriptor ``fd`` every ``interval_s`` (waiting up to ``wait_s`` for a
    first byte), from construction until ``close``; a context manager."""

    def __init__(self, fd: int, interval_s: float, wait_s: float) -> None:
        self._process = subprocess.Popen(
            [sys.executable, "-I", "-S", __file__, str(fd), repr(interval_s), repr(wait_s)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            pass_fds=(fd,),
            start_new_session=True,  # Ctrl-C and a hang-up reach the recorder, which stops it
        )
        assert self._process.stdin is not None and self._process.stdout is not None
        self._control = self._process.stdin
        self._out = self._process.stdout.fileno()
        with contextlib.suppress(OSError):  # an older kernel or a lower limit: the default 64 KiB
            fcntl.fcntl(self._out, fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        self._buffer = bytearray()
        self.stopping = False

    @property
    def pid(self) -> int:
        return self._process.pid

    @property
    def realtime(self) -> bool:
        """Whether the process got the real-time priority it asks for (False once it has ended)."""
        try:
            return os.sched_getscheduler(self.pid) == os.SCHED_FIFO
        except OSError:
            return False

    def __enter__(self) -> ReadProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def stop(self) -> None:
        """Ask the process to read once more, send it and end (``chunks`` gives it all)."""
        if not self.stopping:
            self.stopping = True
            with contextlib.suppress(OSError):
                self._control.close()

    def chunks(self, stop: threading.Event, poll_s: float = 0.1) -> Iterator[Chunk]:
        """Every chunk the process sends, in order, until it ends; once ``stop`` is set the process is
        stopped, and what it read before comes out first. It ended on its own (killed) when ``stopping``
        is still False afterwards."""
        while True:
            if stop.is_set():
                self.stop()
            while (chunk := self._next()) is not None:
                yield chunk
                if chunk.gone is not None:
                    return
            if not select.select([self._out], [], [], poll_s)[0]:
                continue
            data = os.read(self._out, PIPE_BYTES)
            if not data:  # it ended (a message cut short: it was killed; ``stopping`` tells the caller)
                return
            self._buffer += data

    def exit_note(self) -> str:
        """How the process ended, in words (while it runs: "running")."""
        code = self._process.poll()
        return "running" if code is None else f"exit code {code}"

    def _next(self) -> Chunk | None:
        if len(self._buffer) < HEADER.size:
            return None
        kind, host_t, monotonic_s, length = HEADER.unpack_from(self._buffer)
        end = HEADER.size + length
        if len(self._buffer) < end:
            return None
        data = bytes(self._buffer[HEADER.size : end])
        del self._buffer[:end]
        if kind == GONE:
            return Chunk(b"", host_t, monotonic_s, data.decode(errors="replace"))
        return Chunk(data, host_t, monotonic_s)

    def close(self) -> None:
        """Stop the process and wait for it (bounded; then it is killed); what it still sends is dropped."""
        self.stop()
        deadline = time.monotonic() + END_WAIT_S
        with contextlib.suppress(OSError):
            while time.monotonic() < deadline:  # a process waiting on a full pipe is let go
                if select.select([self._out], [], [], 0.05)[0] and not os.read(self._out, PIPE_BYTES):
                    break
        try:
            self._process.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()
        finally:
            assert self._process.stdout is not None
            self._process.stdout.close()


# ---- the process itself (standard library only) ----------------------------------------


def _send(kind: int, data: bytes) -> None:
    message = HEADER.pack(kind, time.time(), time.monotonic(), len(data)) + data
    view = memoryview(message)
    while view:
        view = view[os.write(OUT, view) :]


def _read_available(fd: int) -> bytes:
    """What the port holds now (b"" when nothing); OSError when it failed or is gone."""
    parts: list[bytes] = []
    while select.select([fd], [], [], 0)[0]:
        try:
            data = os.read(fd, 65536)
        except BlockingIOError:
            break
        if not data:
            if parts:
                break
            raise OSError(NO_DATA)
        parts.append(data)
    return b"".join(parts)


def _serve(fd: int, interval_s: float, wait_s: float) -> None:
    """Read every ``interval_s`` until the control pipe says stop (or closes); see the module docstring."""
    next_read = 0.0
    while True:
        if select.select([CONTROL], [], [], max(0.0, next_read - time.monotonic()))[0]:
            _send(DATA, _read_available(fd))  # stopping: what has arrived, then the end
            return
        next_read = time.monotonic() + interval_s
        if fd in select.select([fd, CONTROL], [], [], wait_s)[0]:
            _send(DATA, _read_available(fd))
        else:
            _send(DATA, b"")  # a quiet read: the driver counts the silence and confirms held frames


def main(argv: list[str]) -> int:
    """The process: ``argv`` is this file, the descriptor, ``interval_s`` and ``wait_s``; exit code 0."""
    fd, interval_s, wait_s = int(argv[1]), float(argv[2]), float(argv[3])
    with contextlib.suppress(OSError):  # not allowed: the normal priority
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    try:
        _serve(fd, interval_s, wait_s)
    except BrokenPipeError:  # the recorder is gone: nobody to read for
        return 0
    except OSError as exc:
        with contextlib.suppress(OSError):
            _send(GONE, str(exc).encode())
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
