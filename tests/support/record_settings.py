"""Record settings for the built-in simulated MTi-G, shared by the tests that record: swath roll at T
from 8 deg, no viewer; each test module states only what it changes."""

from __future__ import annotations

from pathlib import Path

from tankdaq.acquire.daemon import RecordSettings


def sim_record_settings(out: Path, **overrides: object) -> RecordSettings:
    """``RecordSettings`` for ``port="sim"`` writing into ``out``, with ``overrides`` on top."""
    base: dict[str, object] = {
        "port": "sim", "draft": 1.0, "angle_deg": 8.0, "hull": "swath", "out_dir": out, "viewer": "none",
        "sim_seed": 0,  # the same test each time (the simulator draws a new seed when none is given)
    }  # fmt: skip
    return RecordSettings(**{**base, **overrides})  # type: ignore[arg-type]
