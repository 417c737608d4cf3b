"""A line every few seconds while one long, otherwise silent step runs (a build, an install).

A live bar draws nothing in a pipe, a log file or ``make``'s output, and a step that says nothing for a
minute looks hung. ``heartbeat`` says where such a step is from a thread, since the step itself is one
blocking call. ``python -m tankdaq.heartbeat DOING CMD...`` does the same around a command: ``make demo``
runs its installs that way, before tankdaq is installed (this module imports only the standard library).
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

#: Seconds between the lines: a pipe or a log never goes quiet for more than this (10 s is promised).
HEARTBEAT_S = 5.0


def _print(line: str) -> None:
    print(line, flush=True)


@contextmanager
def heartbeat(
    doing: str, write: Callable[[str], None] = _print, every_s: float = HEARTBEAT_S
) -> Iterator[None]:
    """Write ``still DOING (N s)`` every ``every_s`` seconds while the context is open."""
    start = time.monotonic()
    done = threading.Event()

    def beat() -> None:
        while not done.wait(every_s):
            write(f"  still {doing} ({time.monotonic() - start:.0f} s)")

    thread = threading.Thread(target=beat, name="tankdaq-heartbeat", daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def main(argv: list[str]) -> int:
    """``DOING CMD...``: a line, CMD run with a heartbeat, a line with its time; CMD's exit code."""
    if len(argv) < 2:
        print("usage: python -m tankdaq.heartbeat DOING CMD...", file=sys.stderr)
        return 2
    doing, command = argv[0], argv[1:]
    start = time.monotonic()
    _print(f"{doing} ...")
    with heartbeat(doing):
        code = subprocess.call(command)
    ended = "done" if code == 0 else f"failed (exit {code})"
    _print(f"{doing}: {ended} after {time.monotonic() - start:.0f} s")
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
