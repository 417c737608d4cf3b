"""CPU the simulated MTi spends making its MTData2 frames: frame by frame (the baseline) against a block
at a time with numpy (device/simulator/frames.py).

Run: ``.venv/bin/python bench/bench_simulator_cpu.py``. Figures: CPU seconds per device-minute of frames,
at 100 and 400 Hz, for the factory default output configuration, the decay test's (what ``record`` asks
for) and every output the simulator sends, each encoded in the bursts the firmware makes at the tests'
``--sim-speed 4`` (``BURST_S`` of wall time: 6 frames at 100 Hz, 26 at 400 Hz). The baseline is the
``Output`` of commit ``BASELINE`` (its output.py from git, run in this process on the same samples, in
turn with the new one, best of ``REPEATS``); the two give the same bytes (checked). Then the whole
``SimulatorProcess`` streaming ``PROCESS_S`` device seconds to the driver, which configures the decay
outputs at 100 Hz as ``record`` does: the process's own CPU, the baseline's run from that commit's
``src`` tree (``git archive``) on PYTHONPATH.
``--quick`` (run_all's quick mode): a tenth of the counts.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np

from benchjson import QUICK, write_result
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator.firmware import BURST_S
from tankdaq.device.simulator.output import (
    SUPPORTED_OUTPUTS,
    Output,
    default_configuration,
    effective_configuration,
)
from tankdaq.device.simulator.process import SimulatorProcess
from tankdaq.xsens.control import decay_output_configuration
from tankdaq.xsens.mtdata2 import make_xdi

#: The last commit whose simulator encoded its frames one by one.
BASELINE = "a9f0bb1"
REPO = Path(__file__).resolve().parents[1]
SPEED = 4.0
REPEATS = 3
DEVICE_S = 60.0
PROCESS_S = 60.0
CONFIGURATIONS: dict[str, Callable[[int], list]] = {
    "default": default_configuration,
    "decay": lambda hz: effective_configuration(decay_output_configuration(hz)),
    "every output": lambda hz: effective_configuration(
        [(make_xdi(name), hz) for name in sorted(SUPPORTED_OUTPUTS)]
    ),
}


def baseline_output() -> ModuleType:
    """The baseline's device/simulator/output.py, imported beside the current one (the rest is unchanged)."""
    source = subprocess.run(
        ["git", "-C", str(REPO), "show", f"{BASELINE}:src/tankdaq/device/simulator/output.py"],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    spec = importlib.util.spec_from_loader("tankdaq.device.simulator.baseline_output", loader=None)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    module.__package__ = "tankdaq.device.simulator"
    sys.modules[spec.name] = module
    exec(compile(source, f"{BASELINE}:output.py", "exec"), module.__dict__)
    return module


def encoder_cpu(output: object, samples: np.ndarray, burst: int) -> tuple[float, list[bytes]]:
    """CPU seconds to encode ``samples`` in bursts of ``burst`` frames, and the frames."""
    frames: list[bytes] = []
    start = time.process_time()
    for first in range(0, samples.size, burst):
        block = samples[first : first + burst]
        frames += output.encode(block, np.arange(first, first + block.size))  # type: ignore[attr-defined]
    return time.process_time() - start, frames


def encoders(device_s: float, repeats: int) -> tuple[dict, dict]:
    old_module = baseline_output()
    figures: dict[str, dict[str, float]] = {}
    ratios: dict[str, float] = {}
    for rate in (100, 400):
        scenario = hull_scenario(rate_hz=rate, runs=1, release_after_s=10.0, decay_s=device_s)
        samples = scenario.samples()[0][: int(device_s * rate)]
        burst = round(rate * BURST_S * SPEED)
        for name, configuration in CONFIGURATIONS.items():
            new, old = Output(items=configuration(rate)), old_module.Output(items=configuration(rate))
            best = {"old": np.inf, "new": np.inf}
            made: dict[str, list[bytes]] = {}
            for _ in range(repeats):
                for label, output in (("old", old), ("new", new)):
                    cpu, made[label] = encoder_cpu(output, samples, burst)
                    best[label] = min(best[label], cpu)
            if made["new"] != made["old"]:
                raise SystemExit(f"{name} at {rate} Hz: the new frames differ from the baseline's")
            per_minute = {label: cpu * 60.0 / (samples.size / rate) for label, cpu in best.items()}
            case = f"{name} {rate} Hz"
            figures[case] = {
                "old_cpu_s_per_device_minute": round(per_minute["old"], 4),
                "new_cpu_s_per_device_minute": round(per_minute["new"], 4),
                "frames_per_burst": burst,
                "frame_bytes": len(made["new"][0]),
            }
            ratios[case] = round(per_minute["old"] / per_minute["new"], 2)
            print(f"{case:>22}: {per_minute['old']:.3f} -> {per_minute['new']:.3f} CPU s per device-minute "
                  f"({ratios[case]:.1f}x, {burst} frames a burst)", flush=True)  # fmt: skip
    return figures, ratios


def process_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


def streaming(tree: Path | None, device_s: float) -> tuple[float, int]:
    """CPU seconds of a ``SimulatorProcess`` (``tree``: its src on PYTHONPATH) streaming ``device_s`` device
    seconds to the driver, configured as ``record`` configures it (the decay outputs at 100 Hz), and the
    samples the driver read."""
    saved = os.environ.get("PYTHONPATH")
    if tree is not None:
        os.environ["PYTHONPATH"] = str(tree)
    try:
        with (
            SimulatorProcess(hull_scenario(rate_hz=100, runs=2), speed=SPEED) as sim,
            MTiDriver(sim.link, rate_hz=100) as driver,
        ):
            assert sim.pid is not None
            driver.configure()
            start_cpu = process_cpu_s(sim.pid)
            samples = driver.samples(device_s)
            return process_cpu_s(sim.pid) - start_cpu, samples.size
    finally:
        if saved is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = saved


def processes(device_s: float) -> tuple[dict, float]:
    with tempfile.TemporaryDirectory() as folder:
        archive = Path(folder) / "baseline.tar"
        subprocess.run(["git", "-C", str(REPO), "archive", "-o", str(archive), BASELINE, "src"], check=True)
        with tarfile.open(archive) as tar:
            tar.extractall(folder, filter="data")
        old_cpu, old_samples = streaming(Path(folder) / "src", device_s)
    new_cpu, new_samples = streaming(None, device_s)
    figures = {
        "old_cpu_s_per_device_minute": round(old_cpu * 60 / device_s, 3),
        "new_cpu_s_per_device_minute": round(new_cpu * 60 / device_s, 3),
        "old_samples_read": old_samples,
        "new_samples_read": new_samples,
    }
    ratio = round(old_cpu / new_cpu, 2)
    print(
        f"SimulatorProcess, {device_s:g} device s of the decay outputs at 100 Hz: "
        f"{old_cpu:.2f} -> {new_cpu:.2f} CPU s ({ratio:.1f}x)"
    )
    return figures, ratio


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", default=QUICK, help="a tenth of the counts")
    args = parser.parse_args()
    device_s, process_s = (DEVICE_S / 10, PROCESS_S / 10) if args.quick else (DEVICE_S, PROCESS_S)
    figures, ratios = encoders(device_s, REPEATS)
    figures["simulator process"], ratios["simulator process"] = processes(process_s)
    write_result(
        "simulator_cpu",
        "CPU seconds per device-minute of MTData2 frames: the simulated MTi's encoder, frame by frame "
        f"against a block at a time with numpy, in the firmware's bursts at --sim-speed {SPEED:g}; and its "
        "whole process streaming to the driver",
        counts={"device_s": device_s, "process_device_s": process_s, "repeats": REPEATS, "speed": SPEED},
        figures=figures,
        ratios=ratios,
        baseline=f"commit {BASELINE}'s frame-by-frame Output.encode (and its whole src tree for the process)",
        quick=args.quick,
    )


if __name__ == "__main__":
    main()
