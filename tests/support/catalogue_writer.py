"""A writer of the two-writers test: N decay rows, one transaction each, into the catalogue at URL.

Run as ``python catalogue_writer.py URL TAG N GO_FILE``: opens the catalogue, says "ready", waits for
GO_FILE (so both writers start together), writes, exits 0.
"""

from __future__ import annotations

import hashlib
import sys
import time
from pathlib import Path

from tankdaq.catalogue.database import open_catalogue
from tankdaq.catalogue.rows import utc_now
from tankdaq.catalogue.writing import upsert_rows

WAIT_S = 60.0


def row(tag: str, number: int) -> dict[str, object]:
    now = utc_now()
    return {
        "sha256": hashlib.sha256(f"{tag}-{number}".encode()).hexdigest(),
        "path": f"/lab/{tag}/decay{number:04d}.mcap",
        "size_bytes": 1000 + number,
        "complete": True,
        "hull": "swath",
        "draft": "T",
        "axis": "roll",
        "created_utc": now,
        "updated_utc": now,
    }


def main(url: str, tag: str, count: int, go: Path) -> int:
    with open_catalogue(url) as catalogue:
        print("ready", flush=True)
        deadline = time.monotonic() + WAIT_S
        while not go.exists():  # the other writer is opening too: start together
            if time.monotonic() > deadline:
                return 3
            time.sleep(0.001)
        for number in range(count):
            with catalogue.engine.begin() as connection:
                upsert_rows(connection, [row(tag, number)], ["path"])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], int(sys.argv[3]), Path(sys.argv[4])))
