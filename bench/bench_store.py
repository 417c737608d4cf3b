"""What recording costs: CPU per sample at 400 Hz, flush+fsync, file size, read-back, recovery, rerun logging.

Run: .venv/bin/python bench/bench_store.py   (prints one line per figure; about 30 s)
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchjson import write_result
from tankdaq.physics.decay import simulate_decay
from tankdaq.samples import SAMPLE_DTYPE
from tankdaq.store import schemas
from tankdaq.store.reader import StoredRecording, read_recording
from tankdaq.store.reader import _read_scanned as read_recording_scanned
from tankdaq.store.recover import recover
from tankdaq.store.writer import RecordingWriter
from tankdaq.viz.live import LiveView

RATE_HZ = 400
MINUTES = 2
BATCH = 4  # samples per driver read at 400 Hz: one batch every 10 ms
RAW_BYTES_PER_SAMPLE = 80  # an MTData2 frame with time, counter, Euler, rate, acceleration, status


def make_samples(n: int) -> np.ndarray:
    rng = np.random.default_rng(1)
    samples = np.zeros(n, dtype=SAMPLE_DTYPE)
    samples["t"] = np.arange(n) / RATE_HZ
    samples["ticks"] = np.arange(n) * (10_000 // RATE_HZ)
    samples["host_t"] = 1.79e9 + samples["t"]
    samples["counter"] = np.arange(n) % 65536
    decay = samples["t"] < 10.0  # a 10 s decay, then rest: the angles' digits look like real data
    samples["roll"][decay], samples["p"][decay] = simulate_decay(
        {"b1": 0.3, "c1": 40.0}, samples["t"][decay], 0.14
    )
    for name in ("pitch", "yaw", "q", "r", "ax", "ay", "az"):
        samples[name] = rng.normal(0, 0.01, n)
    return samples


def cpu_seconds(read: Callable[[Path], StoredRecording], path: Path) -> float:
    """CPU time of one read (the machine is shared: wall time measures the neighbours)."""
    start = time.process_time()
    recording = read(path)
    elapsed = time.process_time() - start
    assert recording.samples.size == RATE_HZ * 60 * MINUTES
    return elapsed


def per_sample_us(seconds: float, n: int) -> float:
    return seconds / n * 1e6


def bench_json(samples: np.ndarray) -> dict[str, float]:
    """Building the per-sample JSON column-wise against a dict and json.dumps per sample."""
    n = samples.size
    start = time.process_time()
    texts = schemas.samples_to_json(samples)
    column_wise = time.process_time() - start
    names = list(schemas.SAMPLE_FIELDS)
    start = time.process_time()
    for row in samples[:20000]:
        json.dumps({name: float(row[schemas.SAMPLE_FIELDS[name][0]]) for name in names})
    per_dict = (time.process_time() - start) / 20000 * n
    print(
        f"JSON building: column-wise {per_sample_us(column_wise, n):.2f} us/sample, "
        f"per-sample dict+json.dumps {per_sample_us(per_dict, n):.2f} us/sample "
        f"({per_dict / column_wise:.1f}x); {sum(map(len, texts)) / n:.0f} bytes/sample"
    )
    return {
        "json_column_wise_us_per_sample": per_sample_us(column_wise, n),
        "json_per_sample_dict_us_per_sample": per_sample_us(per_dict, n),
    }


def bench_write(samples: np.ndarray, frame: bytes, path: Path) -> dict[str, float]:
    """Writing raw bytes and samples as the daemon does, with its flush and fsync twice a second of data."""
    n = samples.size
    writer = RecordingWriter(path, {"hull": "swath", "axis": "roll"}, {}, flush_interval_s=1.0)
    flushes = 0
    start = time.process_time()
    wall = time.perf_counter()
    for k in range(0, n, BATCH):
        writer.write_raw(frame, host_ns=int(samples["host_t"][k] * 1e9))
        writer.write_samples(samples[k : k + BATCH])
        if k % (RATE_HZ // 2) == 0:  # the daemon's clock: a flush is due twice a second of data
            writer.flush()
            flushes += 1
    writer.close()
    cpu = time.process_time() - start
    wall = time.perf_counter() - wall
    size = path.stat().st_size
    print(
        f"write (raw + samples, flush+fsync {flushes}x): {per_sample_us(cpu, n):.1f} us CPU/sample = "
        f"{cpu / (60 * MINUTES) * 100:.2f} % of one core at {RATE_HZ} Hz (wall {wall:.2f} s for "
        f"{60 * MINUTES} s of data)"
    )
    print(
        f"file size: {size / MINUTES / 1e6:.2f} MB per minute at {RATE_HZ} Hz "
        f"({size / n:.0f} bytes/sample incl. raw)"
    )
    return {
        "write_us_cpu_per_sample": per_sample_us(cpu, n),
        "write_cpu_pct_of_one_core_at_400hz": cpu / (60 * MINUTES) * 100,
        "file_mb_per_minute_at_400hz": size / MINUTES / 1e6,
        "file_bytes_per_sample": size / n,
    }


def bench_fsync(folder: Path) -> dict[str, float]:
    fd = os.open(folder / "fsync_probe", os.O_WRONLY | os.O_CREAT)
    start = time.perf_counter()
    for _ in range(50):
        os.write(fd, bytes(4096))
        os.fsync(fd)
    os.close(fd)
    fsync_ms = (time.perf_counter() - start) / 50 * 1e3
    print(f"fsync of a 4 KiB append: {fsync_ms:.2f} ms (this disk)")
    return {"fsync_4kib_ms": fsync_ms}


def bench_read_and_recover(path: Path, n: int) -> dict[str, float]:
    """Reading the file back (by blocks, and scanning the per-sample JSON), and recovering a torn copy."""
    read_s = min(cpu_seconds(read_recording, path) for _ in range(5))
    scan_s = cpu_seconds(read_recording_scanned, path)
    print(
        f"read_recording: {read_s * 1e3:.1f} ms CPU for {n} samples ({n / read_s / 1e6:.2f} M samples/s, "
        f"best of 5); front-to-back scan of the per-sample JSON (files without blocks, cut files): "
        f"{scan_s:.2f} s ({n / scan_s / 1e3:.0f} k samples/s); blocks {scan_s / read_s:.0f}x faster"
    )
    size = path.stat().st_size
    torn = path.with_name("torn.mcap")
    torn.write_bytes(path.read_bytes()[: size * 3 // 4])
    start = time.perf_counter()
    report = recover(torn)
    recover_s = time.perf_counter() - start
    print(
        f"recover: {recover_s:.2f} s for {size * 0.75 / 1e6:.1f} MB "
        f"({size * 0.75 / 1e6 / recover_s:.1f} MB/s), "
        f"{report.messages} messages kept, exit {report.exit_code}"
    )
    return {
        "read_m_samples_per_s_cpu": n / read_s / 1e6,
        "scan_k_samples_per_s_cpu": n / scan_s / 1e3,
        "recover_mb_per_s": size * 0.75 / 1e6 / recover_s,
    }


def bench_rerun(samples: np.ndarray, rrd_path: Path) -> dict[str, float]:
    n = samples.size
    view = LiveView("save", rrd_path=rrd_path)
    start = time.process_time()
    for k in range(0, n, 40):  # the live loop logs every 100 ms
        view.log_samples(samples[k : k + 40])
    view.close()
    rr_cpu = time.process_time() - start
    print(
        f"rerun log_samples (save, 40 per call): {per_sample_us(rr_cpu, n):.1f} us CPU/sample = "
        f"{rr_cpu / (60 * MINUTES) * 100:.2f} % of one core at {RATE_HZ} Hz"
    )
    return {"rerun_save_us_cpu_per_sample": per_sample_us(rr_cpu, n)}


def main() -> None:
    n = RATE_HZ * 60 * MINUTES
    samples = make_samples(n)
    frame = bytes(RAW_BYTES_PER_SAMPLE * BATCH)
    print(
        f"workload: {MINUTES} min at {RATE_HZ} Hz = {n} samples, "
        f"batches of {BATCH}, {len(frame)} raw bytes each"
    )
    figures = bench_json(samples)
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as name:
        folder = Path(name)
        figures |= bench_write(samples, frame, folder / "bench.mcap")
        figures |= bench_fsync(folder)
        figures |= bench_read_and_recover(folder / "bench.mcap", n)
        figures |= bench_rerun(samples, folder / "bench.rrd")
    ratios = {
        "json_column_wise_over_per_sample_dict": figures["json_column_wise_us_per_sample"]
        / figures["json_per_sample_dict_us_per_sample"]
    }
    write_result(
        "store",
        "MCAP writing (raw + samples, flush+fsync twice a second), file size, read-back, recovery, rerun "
        "save",
        counts={"rate_hz": RATE_HZ, "minutes": MINUTES, "samples": n, "batch": BATCH},
        figures=figures,
        ratios=ratios,
        baseline="per-sample dict + json.dumps, same run",
    )


if __name__ == "__main__":
    main()
