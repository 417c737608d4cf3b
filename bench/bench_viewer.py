"""The read loop with and without the live view, and the silence that made the false unplug.

1. Scenario: how long the built-in simulator takes to compute its default open-ended scenario
   (21 decays at 100 Hz). Before the fix this ran in the simulator's serving thread once
   streaming began: that long without a byte on the line, against the driver's 3 s silence limit.
2. Read loop: ``record --port sim`` (in-process, default scenario, sim speed 4) until the first
   decay is saved, with ``--viewer none`` (the baseline, same run) and ``--viewer save``: time
   between reads (median, 99th percentile, max; from each block's host arrival time),
   device-gone events, view updates dropped.
"""

from __future__ import annotations

import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchjson import write_result
from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
from tankdaq.acquire.events import DeviceLost, Event, Settled
from tankdaq.acquire.listeners import EventLog
from tankdaq.acquire.pipeline import DecayPipeline
from tankdaq.acquire.read_thread import Read
from tankdaq.acquire.recorder import Recorder
from tankdaq.acquire.sinks import ViewSink
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.simulator import ScriptedSource


def scenario_seconds() -> float:
    scenario = hull_scenario(hull="swath", draft=1.0, axis="roll", angle_deg=8.0, rate_hz=100, runs=21)
    started = time.perf_counter()
    ScriptedSource(scenario).prepare()
    return time.perf_counter() - started


class TimedRecorder(Recorder):
    """The recorder noting when each block was read (its host arrival time) and what the view dropped. The
    reads run on their own thread: the time between them is the read cadence."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.read_t: list[float] = []
        self.dropped = 0

    def _feed(self, pipeline: DecayPipeline, read: Read) -> None:
        self.read_t.append(read.block.host_t)
        super()._feed(pipeline, read)
        self.dropped = next(sink.view.dropped for sink in pipeline.sinks if isinstance(sink, ViewSink))


class TimedDaemon(RecordDaemon):
    """The record daemon with a ``TimedRecorder``; it stops after the first decay."""

    def __init__(self, settings: RecordSettings) -> None:
        self.gone = 0
        super().__init__(settings, sinks=[EventLog(self._event)], recorder=TimedRecorder)

    def _event(self, event: Event) -> None:
        self.gone += isinstance(event, DeviceLost)
        if isinstance(event, Settled):
            self.stop()


def read_loop(viewer: str, out: Path) -> tuple[np.ndarray, int, int]:
    settings = RecordSettings(
        port="sim", draft=1.0, angle_deg=8.0, hull="swath", out_dir=out / viewer, viewer=viewer, sim_speed=4.0
    )
    daemon = TimedDaemon(settings)
    daemon.run()
    recorder = daemon.recorder
    assert isinstance(recorder, TimedRecorder)
    return np.diff(recorder.read_t), daemon.gone, recorder.dropped


def main() -> None:
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    seconds = scenario_seconds()
    print(f"scenario of 21 decays at 100 Hz computed in {seconds:.2f} s (driver silence limit 3 s)")
    with tempfile.TemporaryDirectory() as tmp:
        rows = {viewer: read_loop(viewer, Path(tmp)) for viewer in ("none", "save")}
    base = np.median(rows["none"][0])
    print("| viewer | reads | median ms | p99 ms | max ms | median vs none | device gone | view dropped |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    figures: dict[str, object] = {"scenario_21_decays_s": seconds}
    for viewer, (reads, gone, dropped) in rows.items():
        ms = reads * 1e3
        spread = f"{np.median(ms):.2f} | {np.percentile(ms, 99):.2f} | {ms.max():.1f}"
        print(f"| {viewer} | {reads.size} | {spread} | {np.median(reads) / base:.2f} | {gone} | {dropped} |")
        figures[f"viewer_{viewer}"] = {
            "reads": reads.size,
            "median_ms": np.median(ms),
            "p99_ms": np.percentile(ms, 99),
            "max_ms": ms.max(),
            "device_gone": gone,
            "view_dropped": dropped,
        }
    write_result(
        "viewer",
        "the simulator's scenario computing time (against the driver's 3 s silence limit), and the time "
        "between reads of `record --port sim` until the first decay is saved, with --viewer none and "
        "--viewer save",
        counts={"sim_speed": 4.0, "scenario_decays": 21},
        figures=figures,
        ratios={"save_median_read_over_none": float(np.median(rows["save"][0]) / base)},
        baseline="--viewer none, same run",
    )


if __name__ == "__main__":
    main()
