"""Memory with the web viewer: tankdaq's resident set over simulated decays with ``--viewer web`` and a
browser on the page all along (issue 40: flat within 50 MB over 100 decays).

``tankdaq record --port sim --viewer web --viewer-bind 127.0.0.1`` in a process of its own, Debian's
Chromium (headless, through playwright, a small page: only its connection matters here) on the printed
address from the start; at each decay's settle
(its line on stderr) the recorder's VmRSS, and the same with its children (the view process, replaced
every hundred decays, and the web viewer's server, whose buffer is bounded by ``--server-memory-limit``).
The figure is the spread (max - min) after the first decay, when the kernels and the view are warm.
tests/viz/test_web_viewer.py measures the same way (``support.web_browser.SettleMemory``) over its few decays.

Run: .venv/bin/python bench/bench_web_memory.py [--decays 100]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from support.web_browser import FAST_SPEED, memory_over_decays

RESULTS = Path(__file__).resolve().parent / "results" / "web_memory.json"
LIMIT_MB = 50.0


def spread(values: list[float]) -> float:
    """Max - min after the first decay (the warm-up)."""
    warm = values[1:] or values
    return max(warm) - min(warm)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--decays", type=int, default=100)
    decays = parser.parse_args().decays
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "recordings"
        measured = memory_over_decays(
            out, decays, lambda n: print(f"decay {n}/{decays}", end="\r", flush=True)
        )
    own, tree = measured["rss_mb"], measured["rss_with_children_mb"]
    result = {
        "what": "tankdaq record --viewer web, a browser connected: resident set (MB) at each decay's settle",
        "decays": decays,
        "sim_speed": float(FAST_SPEED),
        "rss_mb": [round(v, 1) for v in own],
        "rss_with_children_mb": [round(v, 1) for v in tree],
        "spread_after_first_mb": round(spread(own), 1),
        "spread_with_children_after_first_mb": round(spread(tree), 1),
        "limit_mb": LIMIT_MB,
        "flat": spread(own) <= LIMIT_MB,
        "cpu_count": os.cpu_count(),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: v for k, v in result.items() if not k.startswith("rss")}, indent=2))


if __name__ == "__main__":
    main()
