"""The run catalogue: inserts per second (one transaction per decay, as recorders write, and in batches,
as a campaign writes back) into SQLite and a throwaway PostgreSQL server, and a lab's query at 10^5 rows.

Run: ``.venv/bin/python bench/bench_catalogue.py`` (the PostgreSQL part needs the server binaries:
``make test`` installs them where it can). What users need of its figures is in docs/performance.md.
"""

from __future__ import annotations

import hashlib
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from benchjson import write_result
from support.pg_server import throwaway_postgres, why_not
from tankdaq.catalogue.database import Catalogue, open_catalogue, resolve_url
from tankdaq.catalogue.query import RunQuery, select_rows
from tankdaq.catalogue.rows import STANDARD_AMPLITUDES_DEG, utc_now
from tankdaq.catalogue.schema import decays
from tankdaq.catalogue.writing import upsert_rows

SINGLE = 1000
ARCHIVE = 100_000
BATCH = 1000
DRAFTS = ("0.9T", "T", "1.1T")
TERMS = ("b1", "b2", "c1", "c3")


def row(tag: str, number: int) -> dict[str, object]:
    """A decay row as a fit leaves it: condition, fit with intervals, B_eq at the standard amplitudes."""
    month = 1 + number % 12
    return {
        "sha256": hashlib.sha256(f"{tag}-{number}".encode()).hexdigest(),
        "path": f"/lab/{tag}/{number // 1000:03d}/decay{number:06d}.mcap",
        "size_bytes": 50_000 + number % 997,
        "complete": True,
        "recorded_utc": f"{2020 + number % 7}-{month:02d}-15T10:00:00.000+00:00",
        "hull": ("swath", "kvlcc2", "trimaran")[number % 3],
        "draft": DRAFTS[(number // 3) % 3],
        "axis": "roll",
        "angle_nominal_deg": float(2 + number % 12),
        "verdict": "accepted" if number % 10 else "rejected",
        "fit_source": "campaign",
        "fit_model": "b1,b2,c1,c3",
        "coefficients": {
            t: {"value": 0.1, "ci_low": 0.09, "ci_high": 0.11} for t in ("b1", "b2", "c1", "c3")
        },
        "natural_period_s": 1.6,
        "b_eq_per_s": {f"{a:g}": 0.3 for a in STANDARD_AMPLITUDES_DEG},
        "r2_angle": 0.999,
        "warnings": [],
        "created_utc": utc_now(),
        "updated_utc": utc_now(),
    }


def inserts(catalogue: Catalogue, tag: str) -> tuple[float, float]:
    """Rows per second, one transaction each and in batches of ``BATCH``."""
    start = time.perf_counter()
    for number in range(SINGLE):
        with catalogue.engine.begin() as connection:
            upsert_rows(connection, [row(tag, number)], ["path"])
    single = SINGLE / (time.perf_counter() - start)
    rows = [row(tag + "-batch", n) for n in range(10 * BATCH)]
    start = time.perf_counter()
    for first in range(0, len(rows), BATCH):
        with catalogue.engine.begin() as connection:
            upsert_rows(connection, rows[first : first + BATCH], ["path"])
    return single, len(rows) / (time.perf_counter() - start)


def archive_query(catalogue: Catalogue) -> tuple[int, float]:
    """Fill to ``ARCHIVE`` rows, then the lab's question: hull, draft, since, accepted (best of 5)."""
    with catalogue.engine.begin() as connection:
        connection.execute(decays.insert(), [row("archive", n) for n in range(ARCHIVE)])
    query = RunQuery({"hull": "swath", "draft": "1.1T", "verdict": "accepted"}, since="2024-03")
    best, found = float("inf"), 0
    for _ in range(5):
        start = time.perf_counter()
        found = len(select_rows(catalogue, query))
        best = min(best, time.perf_counter() - start)
    return found, best


def measure(name: str, url: str) -> dict[str, float]:
    with open_catalogue(url) as catalogue:
        single, batched = inserts(catalogue, name)
        found, seconds = archive_query(catalogue)
    print(
        f"{name}: {single:,.0f} rows/s one transaction each, {batched:,.0f} rows/s in batches of {BATCH}; "
        f"query at {ARCHIVE + SINGLE + 10 * BATCH:,} rows: {found} rows in {seconds * 1e3:.0f} ms",
        flush=True,
    )
    return {
        "rows_per_s_one_transaction_each": single,
        f"rows_per_s_batches_of_{BATCH}": batched,
        "query_ms": seconds * 1e3,
        "query_rows_found": found,
    }


def main() -> int:
    print(
        f"{platform.node()} {platform.processor() or platform.machine()}, Python {platform.python_version()}"
    )
    with tempfile.TemporaryDirectory() as folder:
        figures = {"sqlite_wal": measure("SQLite (WAL)", f"sqlite:///{Path(folder) / 'catalogue.sqlite'}")}
    reason = why_not()
    if reason is not None:
        print(f"PostgreSQL: skipped ({reason})")
    else:
        with throwaway_postgres() as url:
            resolved = resolve_url(url)
            assert resolved is not None
            figures["postgresql"] = measure("PostgreSQL", resolved)
    write_result(
        "catalogue",
        "run catalogue inserts per second (one transaction per decay, and in batches) and a lab's query "
        "(hull, draft, since, accepted; best of 5) at about 10^5 rows, in SQLite and a throwaway PostgreSQL",
        counts={"single_inserts": SINGLE, "batch": BATCH, "archive_rows": ARCHIVE + SINGLE + 10 * BATCH},
        figures=figures,
        note=None if reason is None else f"PostgreSQL skipped: {reason}",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
