"""How many pytest workers ``make test`` starts: two per core, at least one per core and at most eight
beyond that (Makefile, bench/bench_suite.py --full).

A quarter to a half of each worker's time is spent waiting on real time (a simulated device's decay, a
server, a browser); a second worker on the core takes that time. Past eight, more workers only add
interpreters to a machine that already has cores for every long test.
"""

from __future__ import annotations

import os


def worker_count() -> int:
    """The worker count for this machine's cores."""
    n = os.cpu_count() or 1
    return min(2 * n, max(n, 8))


if __name__ == "__main__":
    print(worker_count())
