"""The record loop's longest pause during a decay, cold and warm numba cache, before and after.

Each case records one simulated decay (swath at T from 8 deg, 100 Hz, simulator at 4x, no
viewer) in a fresh process and notes the wall time of every pass of the read loop (the
daemon's status callback) from the release to the first pass after the settle. The longest
gap between passes is how long acquisition was held up.

"before" is ``--baseline REV``'s source (``git archive``; its tree must have ``acquire.events``), run in the
same session as "after" (this tree); ``--baseline none`` (the default) measures this tree alone.
"cold": ``NUMBA_CACHE_DIR`` and
``TANKDAQ_KERNEL_DIR`` (where the native kernels are built) are a fresh folder (a first run after
install); "warm": the same folder again.

Third figure: the same 20 ms loop, bare, while the kernels compile (cold) on another thread:
what warming up in the background during the device's opening would cost the loop.
Release to fit: in each decay, the seconds of data after the release that the first published live fit
covers and that fit's own time (at real time the first fit shows about their sum after the release).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import subprocess
import sys
import tarfile
import tempfile
import threading
import time
from io import BytesIO
from pathlib import Path

from benchjson import write_result

REPO = Path(__file__).resolve().parents[1]
BASELINE = "none"


def measure_decay(out: Path) -> dict[str, object]:
    """One decay through the record daemon; the loop's pauses from the release to the settle."""
    from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
    from tankdaq.acquire.events import DeviceLost, Event, Fitted, Released, Settled
    from tankdaq.acquire.listeners import EventLog
    from tankdaq.store.reader import read_recording

    passes: list[float] = []
    phase = {"state": "before"}
    fits: list[tuple[float, float]] = []  # (data after the release s, the fit's own s) of each live fit
    release_t = [0.0]

    def on_event(event: Event) -> None:
        if event.printed:
            print(f"{time.monotonic() - started:7.2f} {event.line()}", file=sys.stderr, flush=True)
        if isinstance(event, Released):
            phase["state"], release_t[0] = "decay", event.t_s
        elif isinstance(event, Fitted):
            fits.append((event.result.t_end - release_t[0], event.result.elapsed_s))
        elif isinstance(event, Settled) and phase["state"] == "decay":
            phase["state"] = "settled"

    def on_status(_status: object) -> None:
        if phase["state"] in ("decay", "settled") and not phase.get("done"):
            passes.append(time.monotonic())
            phase["done"] = phase["state"] == "settled"

    started = time.monotonic()
    settings = RecordSettings(
        port="sim", draft=1.0, angle_deg=8.0, hull="swath", out_dir=out, viewer="none", runs=1,
        sim_speed=4.0, sim_seed=4,
    )  # fmt: skip
    heard = EventLog(on_event)
    daemon = RecordDaemon(settings, on_status=on_status, sinks=[heard])
    (outcome,) = daemon.run()
    gaps = [b - a for a, b in itertools.pairwise(passes)]
    return {
        "longest_pause_s": max(gaps),
        "pauses_over_0.1s": sum(g > 0.1 for g in gaps),
        "device_gone": len(heard.of(DeviceLost)),
        "counter_gaps": daemon.status.gaps,
        "wall_s": time.monotonic() - started,
        "fits_in_file": len(read_recording(outcome.path).fits),
        "fits_published": len(fits),
        "first_fit_data_after_release_s": fits[0][0] if fits else None,
        "first_fit_own_s": fits[0][1] if fits else None,
        "longest_fit_own_s": max((own for _, own in fits), default=None),
    }


def measure_compile_beside_a_loop() -> dict[str, float]:
    """A bare 20 ms loop while the kernels compile on another thread: its longest pause."""
    from tankdaq.live.preparation import prepare_kernels

    gaps = _ticks_while(threading.Thread(target=prepare_kernels))
    return {
        "compile_s": sum(gaps),
        "longest_pause_s": max(gaps),
        "pauses_over_0.1s": sum(g > 0.1 for g in gaps),
    }


def _ticks_while(busy: threading.Thread | None, seconds: float = 0.0) -> list[float]:
    """Pauses of a 20 ms loop (the read loop's spacing) while ``busy`` runs, or for ``seconds``."""
    ticks = [time.monotonic()]
    if busy is not None:
        busy.start()
    while busy.is_alive() if busy is not None else ticks[-1] - ticks[0] < seconds:
        time.sleep(0.02)
        ticks.append(time.monotonic())
    return [b - a for a, b in itertools.pairwise(ticks)]


def measure_fits_beside_a_loop() -> dict[str, float]:
    """The GIL question: a 20 ms loop while final fits of a 25 s decay run back to back on a thread."""
    import numpy as np

    from tankdaq.live.identifier import OnlineIdentifier
    from tankdaq.live.preparation import prepare_kernels

    prepare_kernels()
    t = np.arange(0.0, 25.0, 0.01)
    angle = 0.14 * np.exp(-0.15 * t) * np.cos(3.77 * t) + 0.0005 * np.random.default_rng(1).standard_normal(
        t.size
    )
    fit_s: list[float] = []

    def fits() -> None:
        for _ in range(10):
            identifier = OnlineIdentifier("ittc-quadratic-restoring")
            identifier.update(t, angle, np.gradient(angle, t))
            started = time.perf_counter()
            identifier.finish()
            fit_s.append(time.perf_counter() - started)

    busy = _ticks_while(threading.Thread(target=fits))
    idle = _ticks_while(None, seconds=sum(busy))
    return {
        "fit_median_s": float(np.median(fit_s)),
        "longest_pause_fitting_s": max(busy),
        "longest_pause_idle_s": max(idle),
        "median_pause_fitting_s": float(np.median(busy)),
        "median_pause_idle_s": float(np.median(idle)),
    }


def _child(what: str, source: Path, cache: Path) -> dict[str, object]:
    env = {
        **os.environ,
        "PYTHONPATH": str(source),
        "NUMBA_CACHE_DIR": str(cache),
        "TANKDAQ_KERNEL_DIR": str(cache),
    }
    with tempfile.TemporaryDirectory() as out:
        done = subprocess.run(
            [sys.executable, __file__, "--child", what, "--out", out],
            env=env, capture_output=True, text=True, check=True,
        )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def _export(commit: str, into: Path) -> Path:
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", commit, "src", "configs"], capture_output=True, check=True
    )
    with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
        tar.extractall(into, filter="data")
    return into / "src"


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--child", choices=("decay", "compile", "fits"))
    parser.add_argument("--out", type=Path)
    parser.add_argument("--baseline", default=BASELINE)
    args = parser.parse_args()
    if args.child == "decay":
        print(json.dumps(measure_decay(args.out)))
        return
    if args.child == "compile":
        print(json.dumps(measure_compile_beside_a_loop()))
        return
    if args.child == "fits":
        print(json.dumps(measure_fits_beside_a_loop()))
        return
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}, Python {platform.python_version()}")  # fmt: skip
    figures: dict[str, dict[str, object]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        sources = {"after": REPO / "src"}
        if args.baseline != "none":
            sources = {"before": _export(args.baseline, Path(tmp) / "before")} | sources
        for name, source in sources.items():
            cache = Path(tmp) / f"cache-{name}"
            for temperature in ("cold", "warm"):
                result = _child("decay", source, cache)
                label = args.baseline if name == "before" else "this tree"
                print(f"{name} ({label}), {temperature} cache: {result}", flush=True)
                figures[f"decay_{name}_{temperature}"] = result
        with tempfile.TemporaryDirectory() as cold:
            figures["compile_beside_loop_cold"] = _child("compile", REPO / "src", Path(cold))
            print(f"compiling beside a 20 ms loop (cold cache): {figures['compile_beside_loop_cold']}")
            figures["fits_beside_loop_warm"] = _child("fits", REPO / "src", Path(cold))
            print(f"fitting beside a 20 ms loop (warm cache): {figures['fits_beside_loop_warm']}")
    ratios = (
        {}
        if args.baseline == "none"
        else {
            f"longest_pause_{t}_after_over_before": float(figures[f"decay_after_{t}"]["longest_pause_s"])  # type: ignore[arg-type]
            / float(figures[f"decay_before_{t}"]["longest_pause_s"])  # type: ignore[arg-type]
            for t in ("cold", "warm")
        }
    )
    write_result(
        "live_fit",
        "one simulated decay recorded (swath, 100 Hz, simulator at 4x, no viewer) in a fresh process, cold "
        "and "
        "warm kernel cache: the read loop's longest pause, and the first live fit after the release",
        counts={"decays_per_case": 1, "sim_speed": 4.0},
        figures=figures,
        ratios=ratios,
        baseline=f"commit {args.baseline}'s source (git archive), same run",
    )


if __name__ == "__main__":
    main()
