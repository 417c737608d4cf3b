"""Reading a .rrd back with rerun's own reader, for the tests of every command that writes one."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from rerun.chunk import RrdReader


def read_rrd(path: Path) -> tuple[dict[str, list[float]], list[str]]:
    """Scalars per entity and the text log of a .rrd, read back with rerun's own reader."""
    scalars: dict[str, list[float]] = defaultdict(list)
    texts: list[str] = []
    reader = RrdReader(path)
    (recording,) = reader.recordings()
    for chunk in reader.stream(store=recording).to_chunks():
        batch = chunk.to_record_batch()
        if "Scalars:scalars" in batch.schema.names:
            scalars[chunk.entity_path] += [v[0] for v in batch.column("Scalars:scalars").to_pylist() if v]
        if "TextLog:text" in batch.schema.names:
            texts += [v[0] for v in batch.column("TextLog:text").to_pylist() if v]
    return scalars, texts
