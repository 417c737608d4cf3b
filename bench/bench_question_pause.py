"""A long pause at a guided session's question: what piles up while the operator thinks.

A one-condition session (swath roll at T from 10 deg) on the built-in simulated MTi-G at real time
(100 Hz, 20 ms reads), whose operator says the draft is ready at once and then pauses ``--pause``
seconds at the verdict question. Every second of the pause the operator reads the reading thread's
queue (blocks read and not yet fed to the pipeline) and the process's ``VmRSS``; at the end it answers
"skip" (no report is fitted). Each tree runs in a child process of its own (``--baseline-src``: the
``src/`` of ``git archive COMMIT src`` on PYTHONPATH, as bench_memory_day.py does).

Run: .venv/bin/python bench/bench_question_pause.py [--pause 60] [--baseline-src DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchjson import write_result

PLAN = """hulls = ["swath"]
axis = "roll"
drafts = ["T"]
angles_deg = [10.0]
"""


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class PausingOperator:
    """Ready at once; at the verdict, a pause of ``pause_s`` with the queue and RSS read every second."""

    def __init__(self, pause_s: float) -> None:
        self.pause_s = pause_s
        self.session: Any = None
        self.samples: list[tuple[float, int, float]] = []  # (s into the pause, queued blocks, RSS MB)

    def ask(self, question: Any) -> str:
        if question.kind == "draft":
            return ""
        started = time.monotonic()
        while (elapsed := time.monotonic() - started) < self.pause_s:
            queued = self.session.stream.recorder.queued_blocks
            self.samples.append((elapsed, queued, _rss_mb()))
            time.sleep(1.0)
        return "s"


def child(pause_s: float) -> None:
    from tankdaq.config.plans import load_campaign_plan
    from tankdaq.session.runner import GuidedSession, SessionSettings

    with tempfile.TemporaryDirectory() as folder:
        plan = Path(folder) / "plan.toml"
        plan.write_text(PLAN)
        record = {"port": "sim", "out_dir": Path(folder) / "out", "viewer": "none", "sim_seed": 1}
        settings = SessionSettings(load_campaign_plan(str(plan)), "swath", record, sim_faults={})
        operator = PausingOperator(pause_s)
        session = GuidedSession(settings, operator)
        operator.session = session
        session.run()
    first, last = operator.samples[0], operator.samples[-1]
    print(
        json.dumps(
            {
                "max_queued_blocks": max(q for _, q, _ in operator.samples),
                "queued_at_end": last[1],
                "rss_growth_mb": last[2] - first[2],
                "pause_s": last[0],
            }
        )
    )


def run_tree(src: Path | None, pause_s: float) -> dict[str, float]:
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = str(src)
        env.setdefault("TANKDAQ_CONFIG_DIR", str(Path(__file__).resolve().parents[1] / "configs"))
    out = subprocess.run(
        [sys.executable, __file__, "--child", "--pause", str(pause_s)],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--pause", type=float, default=60.0)
    parser.add_argument("--baseline-src", type=Path)
    parser.add_argument("--child", action="store_true")
    args = parser.parse_args()
    if args.child:
        child(args.pause)
        return
    print(f"{platform.node()} {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}, pause {args.pause:g} s")
    trees = [("this tree", None)] + ([("baseline", args.baseline_src)] if args.baseline_src else [])
    figures = {}
    for name, src in trees:
        r = figures[name] = run_tree(src, args.pause)
        print(
            f"{name:>10}: max queued {r['max_queued_blocks']:.0f} blocks, "
            f"at the end {r['queued_at_end']:.0f}, RSS growth over the pause {r['rss_growth_mb']:+.1f} MB"
        )
    write_result(
        "question_pause",
        "a guided session on the simulated MTi-G paused at its verdict question: blocks queued by the "
        "reading thread and RSS growth over the pause",
        counts={"pause_s": args.pause},
        figures=figures,
        baseline=f"--baseline-src {args.baseline_src} (row 'baseline'), same run"
        if args.baseline_src
        else None,
    )


if __name__ == "__main__":
    main()
