"""Exporting a long recording (issue 23): each format's wall time and file size, and the read back.

The recording: an hour at 100 Hz (360 000 samples, every sample field), released every 60 s (60 decays),
on a device clock hours in. Each format is written by ``store.export.export_recording`` (HDF5: one file
per decay) and read back with the tool a lab would use (plain ``pd.read_csv``, h5py, pyarrow, scipy), and
checked equal to the recording bit for bit.

Run: .venv/bin/python bench/bench_export.py [SAMPLES]   (default 360000: about a minute on 2 cores)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchjson import write_result
from tankdaq.samples import SAMPLE_DTYPE
from tankdaq.store.export import export_recording
from tankdaq.store.writer import RecordingWriter

RATE_HZ = 100.0
DECAY_S = 60.0


def write_recording(path: Path, n: int) -> Path:
    rng = np.random.default_rng(0)
    samples = np.zeros(n, dtype=SAMPLE_DTYPE)
    samples["ticks"] = 225_680_000 + np.arange(n) * int(1e4 / RATE_HZ)
    samples["t"] = samples["ticks"] / 1e4
    samples["counter"] = np.arange(n) % 65536
    for field in ("roll", "pitch", "yaw", "p", "q", "r", "ax", "ay", "az"):
        samples[field] = rng.normal(0.0, 0.1, n)
    meta = {"axis": "roll", "hull": "swath", "draft": "T", "angle_nominal_deg": "8"}
    with RecordingWriter(path, meta, {}) as writer:
        for start in range(0, n, 10_000):
            writer.write_samples(samples[start : start + 10_000])
        for release in np.arange(samples["t"][0] + 1.0, samples["t"][-1], DECAY_S):
            writer.write_event("release", "bench", t_s=float(release))
    return path


def read_back(fmt: str, paths: list[Path]) -> np.ndarray:
    """The roll column as the lab's tool reads it."""
    if fmt == "csv":
        import pandas as pd

        return pd.read_csv(paths[0])["roll_rad"].to_numpy()
    if fmt == "h5":
        import h5py

        parts = []
        for path in paths:
            with h5py.File(path, "r") as h5:
                parts.append(h5["roll_rad"][()])
        return np.concatenate(parts)
    if fmt == "parquet":
        import pyarrow.parquet as pq

        return pq.read_table(paths[0])["roll_rad"].to_numpy()
    from scipy.io import loadmat

    return loadmat(paths[0], simplify_cells=True)["tankdaq"]["roll_rad"]


def main() -> int:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 360_000
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        recording = write_recording(folder / "swath_T_roll_8deg_run01.mcap", n)
        from tankdaq.store.reader import read_recording

        roll = read_recording(recording).samples["roll"]
        print(f"{n} samples, recording {recording.stat().st_size / 1e6:.1f} MB")
        print("| format | files | MB | write s | read back s | exact |")
        print("|---|---:|---:|---:|---:|---|")
        figures: dict[str, dict[str, float]] = {"mcap": {"mb": recording.stat().st_size / 1e6}}
        for fmt in ("csv", "h5", "parquet", "mat"):
            start = time.perf_counter()
            paths = export_recording(recording, fmt, folder / fmt)
            wrote = time.perf_counter() - start
            start = time.perf_counter()
            read = read_back(fmt, paths)
            took = time.perf_counter() - start
            size = sum(p.stat().st_size for p in paths) / 1e6
            exact = bool(np.array_equal(read.view(np.uint64), roll.view(np.uint64)))
            print(f"| {fmt} | {len(paths)} | {size:.1f} | {wrote:.2f} | {took:.2f} | {exact} |")
            figures[fmt] = {
                "files": len(paths),
                "mb": size,
                "write_s": wrote,
                "read_back_s": took,
                "exact": exact,
            }
    write_result(
        "export",
        "a recording at 100 Hz (every sample field, a release every 60 s) exported to each format, its size, "
        "wall time, and the read back with a lab's tool checked bit for bit",
        counts={"samples": n, "rate_hz": 100},
        figures=figures,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
