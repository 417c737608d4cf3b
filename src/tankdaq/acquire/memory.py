"""Giving the C allocator's free memory back to the system after each decay.

A decay's buffers (its fit, its file, its .rrd) are freed when it ends, but glibc's malloc keeps the
freed pages of its arenas (each thread that allocates attaches to one, up to 8 per core: the pipeline,
the live fit's worker, the view, rerun's threads) for later, and only the top of each arena is ever
returned by itself. Over a lab day that is tens of MB held free with the view saving, and the resident
size swings and drifts with it (``bench/bench_memory_day.py``). ``malloc_trim(0)``
returns every whole free page of every arena; it is done once a decay has settled, on the pipeline's
thread (never the reading one). ``limit_arenas`` caps the arenas at the record daemon's start (rerun's
threads alone take 15 on 2 cores, each keeping its own free pages); what ``MALLOC_ARENA_MAX`` does.

``fix_mmap_threshold`` keeps large blocks (a fit's arrays over a decay, 80-250 kB at 400 Hz) in mappings
of their own, given back whole when freed. glibc raises its threshold for that each time such a block is
freed (up to 32 MB), after which they are cut from the arenas instead, and the holes they leave there
grow over a day.

``uncache_numpy_small_blocks`` stops numpy keeping freed array buffers under 1 kB for reuse (up to 7 of
each size in bytes: 3.7 MB when full). A recorder meets new block sizes all day (a read's samples, a
refit's windows), so that cache filled slowly and was most of what the recorder still grew by: glibc
memory in use that tracemalloc, which numpy tells of a buffer's free, does not see (memray found it).
``tune_allocator`` does all three, at the daemon's start.
"""

from __future__ import annotations

import ctypes
import functools
import importlib
import os
import platform
import sys
import tracemalloc
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
#: Arenas a recording process uses at most: each arena keeps free pages of its own, so fewer arenas hold
#: several times less memory free (``bench/bench_memory_day.py``).
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


ALLOCATOR_FIELDS = ("ctx", "malloc", "calloc", "realloc", "free")


class _Allocator(ctypes.Structure):
    """Python's ``PyMemAllocatorEx``, which numpy's ``PyDataMemAllocator`` repeats field for field
    (numpy's ``free`` passes one more argument, the size, which Python's ignores)."""

    _fields_ = [(name, ctypes.c_void_p) for name in ALLOCATOR_FIELDS]


#: Where numpy's ``PyDataMem_DefaultHandler`` is in its C API table (the table only grows, numpy's ABI
#: promise: the slot holds from numpy 1.22, which added it), and where the allocator sits in the
#: ``PyDataMem_Handler`` it holds (after ``char name[127]`` and ``uint8_t version``).
NUMPY_DEFAULT_HANDLER_SLOT = 306
HANDLER_ALLOCATOR_OFFSET = 128
#: Python's raw memory domain (``PYMEM_DOMAIN_RAW``): malloc, calloc, realloc and free themselves.
PYMEM_DOMAIN_RAW = 0


def _plain_raw_allocator() -> bool:
    """Python's raw domain is the C library's own here: no debug hooks (a debug build, ``-X dev``,
    ``PYTHONMALLOC=...debug``), no tracemalloc, CPython on glibc where a call may pass one more
    argument than the function takes (x86-64, AArch64)."""
    return (
        _glibc() is not None
        and sys.implementation.name == "cpython"
        and platform.machine() in ("x86_64", "aarch64")
        and not hasattr(sys, "gettotalrefcount")
        and not sys.flags.dev_mode
        and "debug" not in os.environ.get("PYTHONMALLOC", "")
        and not tracemalloc.is_tracing()
    )


def uncache_numpy_small_blocks() -> bool:
    """Point numpy's default array-buffer allocator at the C library's own malloc and free, so that a
    freed buffer under 1 kB goes back to malloc instead of numpy's cache of them; False where nothing
    was changed (see ``_plain_raw_allocator``; a numpy whose default handler is not the one expected).

    Every context that uses numpy's default handler gets it, threads included (a handler set through
    numpy's ``PyDataMem_SetHandler`` holds for one context only). Buffers made before keep working:
    numpy's default made them with the same malloc. Buffers already in numpy's cache stay there."""
    if not _plain_raw_allocator():
        return False
    try:
        umath = importlib.import_module("numpy._core._multiarray_umath")
    except ImportError:
        return False
    if umath.get_handler_name() != "default_allocator" or umath.get_handler_version() != 1:
        return False
    api = ctypes.pythonapi
    api.PyCapsule_GetName.restype = ctypes.c_char_p
    api.PyCapsule_GetName.argtypes = [ctypes.py_object]
    api.PyCapsule_GetPointer.restype = ctypes.c_void_p
    api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    api.PyMem_GetAllocator.argtypes = [ctypes.c_int, ctypes.POINTER(_Allocator)]
    table = api.PyCapsule_GetPointer(umath._ARRAY_API, api.PyCapsule_GetName(umath._ARRAY_API))
    slot = ctypes.c_void_p.from_address(table + NUMPY_DEFAULT_HANDLER_SLOT * ctypes.sizeof(ctypes.c_void_p))
    capsule = ctypes.c_void_p.from_address(slot.value).value if slot.value else None
    if not capsule:
        return False
    default = ctypes.cast(capsule, ctypes.py_object).value
    handler = api.PyCapsule_GetPointer(default, b"mem_handler")
    if ctypes.string_at(handler) != b"default_allocator":
        return False
    raw = _Allocator()
    api.PyMem_GetAllocator(PYMEM_DOMAIN_RAW, ctypes.byref(raw))
    numpy_allocator = _Allocator.from_address(handler + HANDLER_ALLOCATOR_OFFSET)
    for name in ALLOCATOR_FIELDS:
        setattr(numpy_allocator, name, getattr(raw, name))
    return True


def tune_allocator() -> None:
    """What a process that records all day sets at its start: the arenas capped, the large blocks in
    mappings of their own, numpy's small buffers not cached (the 8 simulated hours of
    ``bench/bench_memory_day.py``)."""
    limit_arenas()
    fix_mmap_threshold()
    uncache_numpy_small_blocks()


def release_free_memory() -> bool:
    """Return the allocator's whole free pages to the system; False where there is no such call."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
