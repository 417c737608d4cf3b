"""Free disk space, asked before each decay and before each .rrd write.

The MCAP is the archive and the .rrd is disposable, so the .rrd stops writing while the
disk still has ``RESERVE_BYTES`` free for MCAP files (about a hundred decays at 400 Hz).
"""

from __future__ import annotations

import shutil
from pathlib import Path

#: Free space kept for MCAP files: the .rrd gives way below it.
RESERVE_BYTES = 128 * 2**20


def free_bytes(path: str | Path) -> int:
    """Free bytes on the file system holding ``path`` (or its nearest existing parent)."""
    where = Path(path).absolute()
    while not where.exists() and where != where.parent:
        where = where.parent
    return shutil.disk_usage(where).free


def megabytes(n: int) -> str:
    """``n`` bytes as people read them: "12.3 MB"."""
    return f"{n / 1e6:.1f} MB"
