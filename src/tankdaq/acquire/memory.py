"""Giving the C allocator's free memory back to the system after each decay.

A decay's buffers (its fit, its file, its .rrd) are freed when it ends, but glibc's malloc keeps the
freed pages of its arenas (each thread that allocates attaches to one, up to 8 per core: the pipeline,
the live fit's worker, the view, rerun's threads) for later, and only the top of each arena is ever
returned by itself. Over a lab day that is some 30 MB held free with the view saving, and the resident
size swings and drifts with it (docs/benchmarks.md, "Memory over a lab day"). ``malloc_trim(0)``
returns every whole free page of every arena; it is done once a decay has settled, on the pipeline's
thread (never the reading one). ``limit_arenas`` caps the arenas at the record daemon's start (rerun's
threads alone took 15 on 2 cores, each keeping its own free pages); what ``MALLOC_ARENA_MAX`` does.

``fix_mmap_threshold`` keeps large blocks (a fit's arrays over a decay, 80-250 kB at 400 Hz) in mappings
of their own, given back whole when freed. glibc raises its threshold for that each time such a block is
freed (up to 32 MB), after which they are cut from the arenas instead, and the holes they leave there are
what kept growing over a day (docs/benchmarks.md). ``tune_allocator`` does both, at the daemon's start.
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys
from collections.abc import Callable


@functools.cache
def _glibc() -> ctypes.CDLL | None:
    """The C library this process runs on when it is glibc; None on another C library or platform."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018 (glibc's own symbol: another C library has none)
    except (OSError, AttributeError):
        return None
    return libc


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``; None elsewhere (nothing to do there)."""
    libc = _glibc()
    if libc is None:
        return None
    trim = libc.malloc_trim
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def _mallopt(parameter: int, value: int, variable: str, tunable: str) -> bool:
    """glibc's ``mallopt(parameter, value)``, unless the user set it (the environment ``variable`` or
    the ``tunable`` in ``GLIBC_TUNABLES``); False where nothing was changed."""
    libc = _glibc()
    if libc is None or variable in os.environ or tunable in os.environ.get("GLIBC_TUNABLES", ""):
        return False
    return bool(libc.mallopt(ctypes.c_int(parameter), ctypes.c_int(value)))


#: glibc's ``mallopt`` parameter for the most arenas (malloc.h's ``M_ARENA_MAX``).
M_ARENA_MAX = -8
#: Arenas a recording process uses at most: over 1.5 simulated hours of the memory bench, glibc's memory
#: held free went from 32-59 MB with its own 15 arenas to 7-9 MB with 2 (docs/benchmarks.md).
ARENAS = 2


def limit_arenas(count: int = ARENAS) -> bool:
    """Cap glibc's arenas at ``count`` for the threads made from now on, unless the user set
    ``MALLOC_ARENA_MAX`` (or glibc's tunables); False where nothing was changed."""
    return _mallopt(M_ARENA_MAX, count, "MALLOC_ARENA_MAX", "arena_max")


#: glibc's ``mallopt`` parameter for the size from which a block is mapped on its own (``M_MMAP_THRESHOLD``).
M_MMAP_THRESHOLD = -3
#: That size, fixed (glibc's own starting value): setting it turns glibc's raising of it off.
MMAP_THRESHOLD = 128 * 1024


def fix_mmap_threshold(size: int = MMAP_THRESHOLD) -> bool:
    """Keep blocks of ``size`` bytes and more in mappings of their own for good, unless the user set
    ``MALLOC_MMAP_THRESHOLD_`` (or glibc's tunables); False where nothing was changed."""
    return _mallopt(M_MMAP_THRESHOLD, size, "MALLOC_MMAP_THRESHOLD_", "mmap_threshold")


def tune_allocator() -> None:
    """What a process that records all day sets at its start: the arenas capped, the large blocks in
    mappings of their own (the 8 simulated hours of ``bench/bench_memory_day.py``)."""
    limit_arenas()
    fix_mmap_threshold()


def release_free_memory() -> bool:
    """Return the allocator's whole free pages to the system; False where there is no such call."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
