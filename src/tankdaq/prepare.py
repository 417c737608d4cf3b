"""Build and compile every kernel once, in one process, before anything runs them side by side.

The identification kernels are built ahead of time into a native module in the user cache folder
(``ident.compiled``, ``ident.user_cache``: later processes load them in a millisecond, without numba)
and, where the native build failed (or ``--jit`` asks, as ``make test`` does: its tests hold the native
module against the JIT), compiled by numba's JIT too.
numba's on-disk cache is written by whichever process compiles a kernel first; processes that
compile the same kernel at the same moment can read each other's half-written cache files (a
``SystemError`` from numba's unpickler). ``make`` runs ``python -m tankdaq.prepare`` after installing
and before the test workers start. ``record`` and ``replay`` prepare the identifier's kernels themselves.
"""

from __future__ import annotations

import math
import sys
import time

from .heartbeat import heartbeat


def prepare(jit: bool = False) -> None:
    """Build (or find) the native kernels and compile (or load) the diving-plane kernels; the JIT's
    identification kernels only when they will run (no native module) or ``jit`` asks (about 20 s of a
    core in a fresh folder, none of it a user's when the native module serves)."""
    from .auv.model import simulate_zigzag
    from .auv.vehicle import load_vehicle
    from .ident.compiled import warm_jit
    from .live.preparation import prepare_kernels

    reason = prepare_kernels()
    if reason is not None:
        print(f"tankdaq.prepare: identifier kernels on numba's JIT, slower to start: {reason}")
    if jit or reason is not None:
        warm_jit()
    simulate_zigzag(load_vehicle("nps_auv2"), math.radians(10), math.radians(10), switches=1)


def prepare_said(jit: bool = False) -> None:
    """``prepare`` with a line when it starts, one every few seconds while it works (the first build
    takes about twenty seconds, with nothing else to show), and one when it is done."""
    start = time.monotonic()
    print("tankdaq: preparing the kernels (built once per machine, about 20 s the first time)", flush=True)
    with heartbeat("preparing the kernels"):
        prepare(jit)
    print(f"tankdaq: kernels ready ({time.monotonic() - start:.0f} s)", flush=True)


if __name__ == "__main__":  # python -m tankdaq.prepare [--jit]
    if not set(sys.argv[1:]) <= {"--jit"}:
        print(
            "usage: python -m tankdaq.prepare [--jit]  (--jit: also compile numba's JIT kernels)",
            file=sys.stderr,
        )
        sys.exit(2)
    prepare_said(jit="--jit" in sys.argv[1:])
