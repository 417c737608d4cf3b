"""Write each test module's time from pytest's durations: ``python tools/module_durations.py LOG...``.

``tests/conftest.py`` hands the modules out longest first (tests/durations.json): xdist gives a whole
module to one worker, and a long module started last runs on alone while the other workers wait at the
end. Refresh the file when the order drifts: run the whole suite with ``--durations=0`` into LOG and
write from it. A module's time is the sum of its tests' setup, call and teardown (the longest seen in
any LOG); modules under a second are left out (their order does not matter).
"""

from __future__ import annotations

import json
import os
import sys
from collections import defaultdict
from pathlib import Path

from mark_slow import LINE

#: Where the conftest reads the times.
DURATIONS = Path(__file__).resolve().parents[1] / "tests" / "durations.json"
#: A module shorter than this (s) is left out.
SHORTEST_S = 1.0


def module_seconds(logs: list[Path]) -> dict[str, float]:
    """Test module (path from the root) -> its tests' phases added up, the longest of the logs."""
    longest: dict[str, float] = {}
    for log in logs:
        total: dict[str, float] = defaultdict(float)
        for line in log.read_text(errors="replace").splitlines():
            found = LINE.match(line)
            if found:
                total[found[3]] += float(found[1])
        for module, seconds in total.items():
            longest[module] = max(longest.get(module, 0.0), seconds)
    return longest


def main(argv: list[str], out: Path = DURATIONS) -> int:
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    logs = [Path(a) for a in argv]
    missing = [str(log) for log in logs if not log.is_file()]
    if missing:
        print(f"module_durations: no such log: {', '.join(missing)}", file=sys.stderr)
        return 2
    seconds = module_seconds(logs)
    kept = {m: round(s, 1) for m, s in sorted(seconds.items(), key=lambda kv: -kv[1]) if s >= SHORTEST_S}
    if not kept:
        print("module_durations: no durations in the logs (run pytest with --durations=0)", file=sys.stderr)
        return 1
    temporary = out.with_name(f".{out.name}.tmp")
    temporary.write_text(json.dumps(kept, indent=1) + "\n")
    os.replace(temporary, out)  # never left half-written
    print(f"module_durations: {len(kept)} modules into {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
