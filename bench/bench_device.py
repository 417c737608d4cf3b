"""The driver on the simulated MTi-G over a real pty: hand-shake, throughput, latency, reconnect.

Run: .venv/bin/python bench/bench_device.py
Both ends run in this one process (the simulator in a thread), so the throughput figures are
a lower bound for the driver alone.
"""

from __future__ import annotations

import time

import numpy as np

from benchjson import write_result
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator import Behaviour, DeviceIdentity, SimulatedMTi
from tankdaq.errors import DeviceGone


def handshake(legacy: bool) -> dict[str, float]:
    times = []
    for _ in range(5):
        with SimulatedMTi(hull_scenario(rate_hz=100), legacy=legacy) as sim, MTiDriver(sim.link) as driver:
            start = time.perf_counter()
            driver.configure()
            times.append(time.perf_counter() - start)
    kind = "legacy" if legacy else "MTData2"
    print(f"hand-shake + configure ({kind}): median {np.median(times) * 1e3:.1f} ms over 5")
    return {f"handshake_{kind.lower()}_ms": float(np.median(times)) * 1e3}


def hard_connects() -> dict[str, float]:
    """Hand-shakes that need more than GoToConfig: a stuck device (Reset, ~1.7 s boot), a baud move."""
    cases = {
        "stuck until Reset, 1.7 s boot": ({"behaviour": Behaviour(stuck=True, boot_s=1.7)}, {}),
        "move 115200 -> 921600 (SetBaudrate)": ({}, {"baud": 921600, "rate_hz": 400}),
        "move 115200 -> 921600 (600-series PortConfig)": (
            {"identity": DeviceIdentity.mti_630()},
            {"baud": 921600, "rate_hz": 400},
        ),
        "found at 460800 by the search": ({"baud": 460800}, {}),
    }
    figures = {}
    for label, (device, driver_options) in cases.items():
        times = []
        for _ in range(3):
            with (
                SimulatedMTi(hull_scenario(rate_hz=driver_options.get("rate_hz", 100)), **device) as sim,
                MTiDriver(sim.link, **driver_options) as driver,
            ):
                start = time.perf_counter()
                driver.configure()
                times.append(time.perf_counter() - start)
        print(f"hand-shake + configure, {label}: median {np.median(times):.2f} s over 3")
        figures[f"handshake_s: {label}"] = float(np.median(times))
    return figures


def throughput(rate_hz: int, baud: int) -> dict[str, float]:
    """Speed-ups of the device clock until samples go missing: the pipeline's headroom."""
    figures = {}
    for speed in (1, 5, 10, 20, 40):
        device_s = 5.0
        with (
            SimulatedMTi(hull_scenario(rate_hz=rate_hz), speed=speed, baud=baud) as sim,
            MTiDriver(sim.link, baud=baud, rate_hz=rate_hz) as driver,
        ):
            driver.configure()
            wall, cpu = time.perf_counter(), time.process_time()
            try:
                samples = driver.samples(device_s)
            except DeviceGone as gone:  # the simulator (in this process) fell silent: past the headroom
                print(f"{rate_hz} Hz at {baud} baud x{speed:<2d}: {gone}")
                figures[f"x{speed}_device_silent"] = 1
                break
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            lost = driver.counters.lost + sim.bytes_overflowed // 69
        print(
            f"{rate_hz} Hz at {baud} baud x{speed:<2d}: {samples.size / wall:8.0f} samples/s received, "
            f"{lost} lost, CPU {cpu / wall:5.1%} of one core (simulator + driver)"
        )
        figures[f"x{speed}_samples_per_s"] = samples.size / wall
        figures[f"x{speed}_cpu_pct_of_one_core"] = cpu / wall * 100
        figures[f"x{speed}_lost"] = lost
        if lost:
            break
    return figures


def latency() -> dict[str, float]:
    """How late samples reach the caller, relative to the device clock (real time, 100 Hz)."""
    with SimulatedMTi(hull_scenario(rate_hz=100)) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        samples = driver.samples(5.0)
    lag = (samples["host_t"] - samples["host_t"][0]) - (samples["t"] - samples["t"][0])
    lag -= lag.min()
    print(f"arrival lag behind device time at 100 Hz: p50 {np.median(lag) * 1e3:.1f} ms, "
          f"p99 {np.percentile(lag, 99) * 1e3:.1f} ms, max {lag.max() * 1e3:.1f} ms")  # fmt: skip
    return {
        "p50_ms": float(np.median(lag)) * 1e3,
        "p99_ms": float(np.percentile(lag, 99)) * 1e3,
        "max_ms": float(lag.max()) * 1e3,
    }


def reconnect() -> float:
    times = []
    for _ in range(5):
        with SimulatedMTi(hull_scenario(rate_hz=100), speed=10) as sim, MTiDriver(sim.link) as driver:
            driver.configure()
            sim.unplug()
            sim.replug()
            start = time.perf_counter()
            driver.reconnect(timeout_s=5)
            driver.samples(0.5)
            times.append(time.perf_counter() - start)
    print(f"re-plug to samples flowing again: median {np.median(times) * 1e3:.0f} ms over 5")
    return float(np.median(times)) * 1e3


def main() -> None:
    figures = {"connect": handshake(legacy=False) | handshake(legacy=True) | hard_connects()}
    figures["throughput_100hz_115200"] = throughput(100, 115200)
    figures["throughput_400hz_921600"] = throughput(400, 921600)
    figures["arrival_lag_100hz"] = latency()
    figures["replug_to_samples_ms"] = reconnect()
    write_result(
        "device",
        "the driver on the simulated MTi-G over a real pty (both in this process): hand-shakes, samples/s "
        "received as the device clock is sped up until samples go missing, arrival lag, re-plug",
        counts={"throughput_device_s": 5.0, "speeds": [1, 5, 10, 20, 40], "handshake_repeats": 5},
        figures=figures,
    )


if __name__ == "__main__":
    main()
