"""A recorder whose live refits run away, for the signal tests and bench/bench_runaway.py.

``python tests/support/runaway_recorder.py OUT_DIR``: the real RecordDaemon on the simulated MTi-G (swath at
T, 8 deg, simulator at 4x), its live identifier given the gyro 1000 times too large (a rate in mrad/s
read as rad/s), a decay the model cannot follow: each refit runs until its budget abandons it. Its own
lines on stdout: ``refit started`` when one begins, at the ``Stopping`` event ``heard <monotonic s>
refit running <bool>`` then ``stop event <signal>``; at the end ``files <n>``. The daemon's event lines
go to stderr. Exits 130 when stopped by a signal.
"""

from __future__ import annotations

import functools
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
from tankdaq.acquire.events import Event, Stopping
from tankdaq.acquire.listeners import EventLog, EventPrinter
from tankdaq.live.identifier import OnlineIdentifier, OnlineResult
from tankdaq.records import DecayRun

GYRO_SCALE = 1000.0
refitting = threading.Event()


class GyroInMilliradians(OnlineIdentifier):
    """The real identifier, given the gyro as a misconfigured sensor would give it."""

    def update(self, t: np.ndarray, angle: np.ndarray, rate: np.ndarray | None = None) -> Any:
        return super().update(t, angle, None if rate is None else np.asarray(rate) * GYRO_SCALE)

    def _refit(self, run: DecayRun, half_cycles: int) -> OnlineResult:
        refitting.set()
        print("refit started", flush=True)
        try:
            return super()._refit(run, half_cycles)
        finally:
            refitting.clear()


def on_event(event: Event) -> None:
    if isinstance(event, Stopping):
        print(f"heard {time.monotonic():.6f} refit running {refitting.is_set()}", flush=True)
        print(f"stop event {event.signal}", flush=True)


def main(out: Path) -> int:
    settings = RecordSettings(
        port="sim",
        hull="swath",
        draft=1.0,
        angle_deg=8.0,
        out_dir=out,
        viewer="none",
        sim_speed=4.0,
        sim_seed=0,
    )
    # the first refit after 8 half-cycles, from a cold start: on this gyro it runs past its budget
    identifier = functools.partial(GyroInMilliradians, min_half_cycles=8)
    printer = EventPrinter(lambda line: print(line, file=sys.stderr, flush=True))
    daemon = RecordDaemon(settings, sinks=[EventLog(on_event), printer], identifier=identifier)
    daemon.run()
    print(f"files {len(daemon.recordings)}", flush=True)
    return 130 if daemon.stopped_by else 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
