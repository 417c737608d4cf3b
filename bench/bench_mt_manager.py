"""MT Manager text exports (issue 41): the fit of a known decay from every export style, against the truth
and against the plain CSV of the same decay; and the cost of reading a long export against a plain CSV of
the same rows and columns, in the same run.

Styles: each MT Manager generation (4.x, 2019.2, 2022.2) x delimiter (tab, comma, semicolon, space) x
orientation (Roll, Euler_X, quaternion, matrix), the time taken in turn from SampleTimeFine without a
wrap, over a one-day wrap, over a 2**32 wrap, and from PacketCounter at a rate (the header's for 4.x,
``--rate`` for the others). The files are written from ``held_tilt``'s decay (``TRUTH``), as the tests
write them (``tests/support/mt_manager_files.py``).

Run: .venv/bin/python bench/bench_mt_manager.py [ROWS]   (48 fits and a ROWS-row read: about two minutes)
"""

from __future__ import annotations

import itertools
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import track

from benchjson import write_result

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import tankdaq
from support.held_tilt import TRUTH, held_tilt
from support.mt_manager_files import write_export
from tankdaq.api.identification import Reading
from tankdaq.store.inputs import read_runs

RESULTS = Path(__file__).resolve().parents[1] / "bench" / "results" / "mt_manager.json"
GENERATIONS = ("4.x", "2019.2", "2022.2")
DELIMITERS = {"tab": "\t", "comma": ",", "semicolon": ";", "space": " "}
KINDS = ("Roll", "Euler", "Quat", "Mat")
TIMES = {
    "SampleTimeFine": {},
    "SampleTimeFine one-day wrap": {"start_tick": 864_000_000 - 20_000},
    "SampleTimeFine 2^32 wrap": {"start_tick": 2**32 - 30_000, "modulus": 2**32},
    "PacketCounter and a rate": {"sample_time": False},
}
MODEL = "ittc-quadratic"


def fit(path: Path, reading: Reading) -> dict[str, float]:
    """b1 and c1 of one file, as ``tankdaq identify`` fits them."""
    found = tankdaq.identify(path, MODEL, reading=reading).document["coefficients"]
    return {term: found[term]["value"] for term in ("b1", "c1")}


def plain_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    np.savetxt(
        path, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments=""
    )
    return path


def fits(folder: Path) -> dict[str, object]:
    """Every style's b1 and c1 against the truth and the plain CSV's."""
    t, angle, _ = held_tilt()
    plain = fit(plain_csv(folder / "plain.csv", {"time_s": t, "angle_deg": np.degrees(angle)}), Reading())
    cases: dict[str, object] = {}
    styles = list(itertools.product(GENERATIONS, DELIMITERS, KINDS))
    for number, (generation, delimiter, kind) in enumerate(track(styles, description="fits")):
        time_name, settings = list(TIMES.items())[number % len(TIMES)]
        name = f"{generation} {delimiter} {kind}, {time_name}"
        path = write_export(
            folder / f"{number}.txt",
            generation,
            kind,
            DELIMITERS[delimiter],
            missing="NaN" * (generation == "2022.2"),
            **settings,
        )
        rate = 100.0 if "sample_time" in settings and generation != "4.x" else None
        found = fit(path, Reading(sample_rate_hz=rate))
        cases[name] = {
            term: {
                "value": value,
                "error_vs_truth_pct": 100 * (value / TRUTH[term] - 1),
                "difference_vs_plain_csv_pct": 100 * (value / plain[term] - 1),
            }
            for term, value in found.items()
        }
    worst = {
        key: max(abs(case[term][key]) for case in cases.values() for term in ("b1", "c1"))  # type: ignore[index]
        for key in ("error_vs_truth_pct", "difference_vs_plain_csv_pct")
    }
    return {
        "truth": {k: TRUTH[k] for k in ("b1", "c1")},
        "plain_csv": plain,
        "worst_abs_pct": worst,
        "cases": cases,
    }


def reading_cost(folder: Path, rows: int) -> dict[str, object]:
    """Seconds to read a ROWS-row 2022.2 tab export (28 columns, quaternion) against the plain CSV of the
    same numbers (best of three each, interleaved)."""
    from support.mt_manager_files import HEADERS, orientation

    rng = np.random.default_rng(0)
    roll = np.radians(8.0) * np.exp(-0.02 * np.arange(rows) / 100) * np.cos(np.arange(rows) / 100 * 3.7)
    names, values = orientation("Quat", roll)
    other = rng.normal(0.0, 1.0, (rows, 21))
    counter = np.arange(rows) % 65_536
    ticks = (1000 + np.arange(rows) * 100) % 864_000_000
    header = ["PacketCounter", "SampleTimeFine", *[f"X{k}" for k in range(21)], *names]
    table = np.column_stack([counter, ticks, other, values])
    export = folder / "long.txt"
    with export.open("w", newline="") as fh:
        fh.write("\r\n".join(HEADERS["2022.2"]) + "\r\n" + "\t".join(header) + "\r\n")
        np.savetxt(fh, table, delimiter="\t", fmt="%.6f", newline="\r\n")
    plain = folder / "long.csv"
    plain_columns = {"time_s": ticks / 10_000, **{f"X{k}": other[:, k] for k in range(21)}}
    plain_columns |= {"angle_deg": np.degrees(roll), **{n: values[:, i] for i, n in enumerate(names)}}
    plain_csv(plain, plain_columns)
    best = {"export": np.inf, "plain_csv": np.inf}
    options = tankdaq.store.csv_import.CsvOptions(keep_all=True)  # type: ignore[attr-defined]
    for _ in range(3):
        for name, path in (("export", export), ("plain_csv", plain)):
            start = time.perf_counter()
            read_runs(path, "roll", options)
            best[name] = min(best[name], time.perf_counter() - start)
    return {
        "rows": rows,
        "columns": len(header),
        "best_s": best,
        "ratio_export_to_plain": best["export"] / best["plain_csv"],
    }


def main() -> None:
    rows = int(sys.argv[1]) if len(sys.argv) > 1 else 200_000
    import tankdaq.store.csv_import  # noqa: F401  (the options of read_runs)

    with tempfile.TemporaryDirectory() as folder:
        results: dict[str, Any] = {"fits": fits(Path(folder)), "reading": reading_cost(Path(folder), rows)}
    write_result(
        "mt_manager",
        "b1 and c1 of a known decay from every MT Manager export style (generation x delimiter x "
        "orientation, four time sources in turn) against the truth and the plain CSV; the time to read a "
        "long export against a plain CSV of the same numbers",
        counts={"rows": rows, "model": MODEL},
        figures=results,
    )
    print(
        json.dumps(
            {k: v for k, v in results.items() if k != "fits"} | {"worst": results["fits"]["worst_abs_pct"]},
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
