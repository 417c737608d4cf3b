"""Reading a long CSV (issue 19): a 10^7-row record of hand-stopped decays, read and split.

The file: ``time_s, angle_deg, rate_deg_s`` at 100 Hz, decays of 3-10 deg (a damped cosine, period
1.7 s, 30 s free), each tilted by hand, held 2 s, released, stopped by hand and left at rest 3 s (36.3 s
a decay: 2755 of them in 10^7 rows, 320 MB of text). Each reading runs in its own process, so its peak
memory (max RSS) is its own:

- baseline: the rows read one by one with the csv module into Python floats (how tankdaq read every
  CSV before issue 19, and still reads a file the fast path refuses: empty cells, text in a column);
- ``read_table``: numpy's C reader streaming the lines (``store.csv_dialect``);
- ``read_decays``: the whole way in (dialect, units from the data, rests found, every decay split).

Run: .venv/bin/python bench/bench_csv_import.py [ROWS]   (10^7 rows: about five minutes on 2 cores)
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchjson import write_result

RATE_HZ = 100.0
OMEGA = 2 * math.pi / 1.7
ZETA = 0.03


def write_record(path: Path, rows: int, seed: int = 0) -> int:
    """Hand-stopped decays until ``rows`` rows; returns how many decays the file holds."""
    rng = np.random.default_rng(seed)
    tf = np.arange(int(30 * RATE_HZ)) / RATE_HZ
    shape = np.exp(-ZETA * OMEGA * tf) * np.cos(OMEGA * math.sqrt(1 - ZETA**2) * tf)
    one = int(36.3 * RATE_HZ)
    n = math.ceil(rows / one)
    with path.open("w") as fh:
        fh.write("time_s,angle_deg,rate_deg_s\n")
        for k in range(n):
            a0 = rng.uniform(3.0, 10.0)
            angle = np.concatenate(
                [
                    np.linspace(0, a0, int(RATE_HZ), endpoint=False),  # tilt by hand
                    np.full(int(2 * RATE_HZ), a0),  # hold
                    a0 * shape,  # free decay
                    a0 * shape[-1] * np.linspace(1, 0, int(0.3 * RATE_HZ)),  # stopped by hand
                    np.zeros(one - int(RATE_HZ) - int(2 * RATE_HZ) - tf.size - int(0.3 * RATE_HZ)),  # rest
                ]
            ) + rng.normal(0, 0.01, one)
            t = (k * one + np.arange(one)) / RATE_HZ
            rate = np.gradient(angle, 1 / RATE_HZ)
            np.savetxt(fh, np.column_stack([t, angle, rate]), delimiter=",", fmt="%.6f")
    return n


READERS = {
    "baseline": (
        "from tankdaq.store.csv_dialect import sniff, _load_checked\n"
        "d, c, h, _ = sniff(path)\n"
        "n = _load_checked(path, d, h, 1, [0, 1, 2], ())[0].shape[0]"
    ),
    "read_table": (
        "from tankdaq.store.csv_dialect import read_table\n"
        "n = len(read_table(path, ('time_s', 'angle_deg')).columns['time_s'])"
    ),
    "read_decays": ("from tankdaq.ident.inputs import read_decays\nn = len(read_decays(path))"),
}


def measure(reader: str, path: Path) -> tuple[float, float, str]:
    """Wall time (s), peak memory (MB) and what it read, in a process of its own."""
    code = (
        "import sys, time, resource\nfrom pathlib import Path\npath = Path(sys.argv[1])\n"
        f"start = time.perf_counter()\n{READERS[reader]}\nwall = time.perf_counter() - start\n"
        "print(wall, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, n)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True
    ).stdout.split()
    return float(out[0]), float(out[1]), out[2]


def main() -> None:
    rows = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "long.csv"
        start = time.perf_counter()
        decays = write_record(path, rows)
        took = time.perf_counter() - start
        size_mb = path.stat().st_size / 1e6
        print(f"{size_mb:.0f} MB, {decays} decays written in {took:.0f} s")
        figures: dict[str, dict[str, float]] = {}
        for reader in READERS:
            wall, peak, what = measure(reader, path)
            unit = "runs" if reader == "read_decays" else "rows"
            print(f"{reader:12s} {wall:7.1f} s  peak {peak:7.0f} MB  ({what} {unit})")
            figures[reader] = {"wall_s": wall, "peak_rss_mb": peak, unit: int(what)}
    write_result(
        "csv_import",
        "reading a long CSV of hand-stopped decays, each reader in its own process: the csv module row by "
        "row (baseline), numpy's reader streaming the lines, and read_decays the whole way in",
        counts={"rows": rows, "decays": decays, "file_mb": size_mb},
        figures=figures,
        ratios={
            name: {
                "wall_over_baseline": row["wall_s"] / figures["baseline"]["wall_s"],
                "peak_over_baseline": row["peak_rss_mb"] / figures["baseline"]["peak_rss_mb"],
            }
            for name, row in figures.items()
            if name != "baseline"
        },
        baseline="the reader named baseline (READERS), same run, same file",
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
