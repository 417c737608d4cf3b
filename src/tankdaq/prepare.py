"""Compile every numba kernel once, in one process, before anything runs them side by side.

numba's on-disk cache is written by whichever process compiles a kernel first; processes that
compile the same kernel at the same moment can read each other's half-written cache files (a
``SystemError`` from numba's unpickler). ``make test`` runs ``python -m tankdaq.prepare`` before its
parallel workers start. ``record`` and ``replay`` prepare the identifier's kernels themselves.
"""

from __future__ import annotations

import math


def prepare() -> None:
    """Compile (or load from the cache) the identification and diving-plane kernels."""
    from .ident.online import prepare_kernels
    from .maneuver.model import simulate_zigzag
    from .maneuver.vehicle import load_vehicle

    prepare_kernels()
    simulate_zigzag(load_vehicle("nps_auv2"), math.radians(10), math.radians(10), switches=1)


if __name__ == "__main__":
    prepare()
