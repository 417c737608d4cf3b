"""The driver on the simulated MTi-G over a real pty: hand-shake, throughput, latency, reconnect.

Run: .venv/bin/python bench/bench_device.py
Both ends run in this one process (the simulator in a thread), so the throughput figures are
a lower bound for the driver alone.
"""

from __future__ import annotations

import time

import numpy as np

from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator import Behaviour, DeviceIdentity, SimulatedMTi


def handshake(legacy: bool) -> None:
    times = []
    for _ in range(5):
        with SimulatedMTi(hull_scenario(rate_hz=100), legacy=legacy) as sim, MTiDriver(sim.link) as driver:
            start = time.perf_counter()
            driver.configure()
            times.append(time.perf_counter() - start)
    kind = "legacy" if legacy else "MTData2"
    print(f"hand-shake + configure ({kind}): median {np.median(times) * 1e3:.1f} ms over 5")


def hard_connects() -> None:
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


def throughput(rate_hz: int, baud: int) -> None:
    """Speed-ups of the device clock until samples go missing: the pipeline's headroom."""
    for speed in (1, 5, 10, 20, 40):
        device_s = 5.0
        with (
            SimulatedMTi(hull_scenario(rate_hz=rate_hz), speed=speed, baud=baud) as sim,
            MTiDriver(sim.link, baud=baud, rate_hz=rate_hz) as driver,
        ):
            driver.configure()
            wall, cpu = time.perf_counter(), time.process_time()
            samples = driver.samples(device_s)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            lost = driver.counters.lost + sim.bytes_overflowed // 69
        print(
            f"{rate_hz} Hz at {baud} baud x{speed:<2d}: {samples.size / wall:8.0f} samples/s received, "
            f"{lost} lost, CPU {cpu / wall:5.1%} of one core (simulator + driver)"
        )
        if lost:
            break


def latency() -> None:
    """How late samples reach the caller, relative to the device clock (real time, 100 Hz)."""
    with SimulatedMTi(hull_scenario(rate_hz=100)) as sim, MTiDriver(sim.link) as driver:
        driver.configure()
        samples = driver.samples(5.0)
    lag = (samples["host_t"] - samples["host_t"][0]) - (samples["t"] - samples["t"][0])
    lag -= lag.min()
    print(f"arrival lag behind device time at 100 Hz: p50 {np.median(lag) * 1e3:.1f} ms, "
          f"p99 {np.percentile(lag, 99) * 1e3:.1f} ms, max {lag.max() * 1e3:.1f} ms")  # fmt: skip


def reconnect() -> None:
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


def main() -> None:
    handshake(legacy=False)
    handshake(legacy=True)
    hard_connects()
    throughput(100, 115200)
    throughput(400, 921600)
    latency()
    reconnect()


if __name__ == "__main__":
    main()
