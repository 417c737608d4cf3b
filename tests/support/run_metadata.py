"""A recording's run metadata as the official ``mcap`` reader reads it: what another tool sees in the file."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader


def run_metadata(path: Path) -> dict[str, str]:
    """The file's last ``tankdaq.run`` metadata record (the seeking reader needs the footer and summary)."""
    with path.open("rb") as f:
        records = [m.metadata for m in make_reader(f).iter_metadata() if m.name == "tankdaq.run"]
    return records[-1]
