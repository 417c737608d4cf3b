"""Giving the C allocator's free memory back to the system after each decay.

A decay's buffers (its fit, its file, its .rrd) are freed when it ends, but glibc's malloc keeps the
freed pages of its arenas (each thread that allocates attaches to one, up to 8 per core: the pipeline,
the live fit's worker, the view, rerun's threads) for later, and only the top of each arena is ever
returned by itself. Over a lab day that is some 30 MB held free with the view saving, and the resident
size swings and drifts with it (docs/benchmarks.md, "Memory over a lab day"). ``malloc_trim(0)``
returns every whole free page of every arena; it is done once a decay has settled, on the pipeline's
thread (never the reading one).
"""

from __future__ import annotations

import ctypes
import functools
import sys
from collections.abc import Callable


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``; None on another C library or platform (nothing to do there)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        trim = ctypes.CDLL(None).malloc_trim  # the C library this process runs on
    except (OSError, AttributeError):  # musl and others have no malloc_trim
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_memory() -> bool:
    """Return the allocator's whole free pages to the system; False where there is no such call."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
