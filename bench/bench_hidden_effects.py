"""The discrepancy workflow's statistical claims at their full count (``tests/support/hidden_effects.py``):

- the workflow's hidden effects: of 20 draws of each hidden effect (and of none), at least 90 % name it
  first, and every draw meets the noise, halves the gap and sizes the effect within 20 % (``make test``
  runs 6 draws of each);
- the prediction sets (issue 39): decays made from the KVLCC2 hull's own simplified Ikeda prediction at
  15.5 kn (0.967 m/s model scale) with one component (lift, wave, friction, eddy) scaled by a random
  factor, compared with the prediction at the decays' speed: in every draw the prediction holds lift,
  no rig friction is named, the scaled component's part is named first with its factor within 20 %, and
  the gap shrinks by >= 70 %; with nothing scaled nothing is named.

Run: .venv/bin/python bench/bench_hidden_effects.py [--draws N] [--set all|workflow|prediction]
  -> bench/results/hidden_effects.json (a set not run keeps its stored results, with their own date)
"""

from __future__ import annotations

import argparse
import datetime
import json
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from rich.progress import track

from benchjson import write_result

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from support.hidden_effects import (
    NAMED_SHARE,
    PREDICTION_CASES,
    diagnose_draw,
    draw_faults,
    named_first,
    prediction_draw,
    prediction_faults,
)
from tankdaq.diagnose.effects import LIBRARY

DRAWS = 20
RESULT = Path(__file__).parent / "results" / "hidden_effects.json"


def _now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


def workflow_set(pool: ProcessPoolExecutor, draws: int) -> dict[str, Any]:
    cases = [("", 2000)] + [(effect.key, 1000) for effect in LIBRARY]
    rows = []
    for key, first_seed in track(cases, description="hidden effects"):
        effects = (key,) if key else ()
        outcomes = list(pool.map(diagnose_draw, [effects] * draws, range(first_seed, first_seed + draws)))
        named = sum(named_first(key, o) for o in outcomes)
        faults = {seed: f for seed, o in enumerate(outcomes, first_seed) if (f := draw_faults(key, o))}
        rows.append({"effect": key or "none", "draws": draws, "named_first": named, "faulty": faults})
        print(f"{key or 'none':28s} named first {named}/{draws}, faulty draws {len(faults)}", flush=True)
    passed = all(r["named_first"] >= NAMED_SHARE * draws and not r["faulty"] for r in rows)
    return {"passed": passed, "cases": rows, "date": _now()}


def prediction_set(pool: ProcessPoolExecutor, draws: int) -> dict[str, Any]:
    rows = []
    for component, band in track(PREDICTION_CASES, description="prediction sets"):
        seeds = range(3000, 3000 + draws)
        outcomes = list(pool.map(prediction_draw, [component] * draws, [band] * draws, seeds))
        faults = {
            seed: f for seed, o in zip(seeds, outcomes, strict=True) if (f := prediction_faults(component, o))
        }
        reductions = [o["gap_reduction"] for o in outcomes]
        errors = [abs(o["factor_alone"] / o["factor"] - 1) for o in outcomes if o["factor_alone"] is not None]
        named = [o["named"] if component else not o["effects"] for o in outcomes]
        rows.append({
            "component": component or "none", "factor_band": list(band), "draws": draws,
            "named_first": sum(named),
            "rig_friction_named": sum("friction.coulomb" in o["effects"] for o in outcomes),
            "gap_reduction_min": min(reductions),
            "gap_reduction_median": sorted(reductions)[len(reductions) // 2],
            "factor_error_max": max(errors) if errors else None, "faulty": faults,
        })  # fmt: skip
        print(
            f"{component or 'none':6s} {band} named {rows[-1]['named_first']}/{draws}, gap >= "
            f"{min(reductions):.0%}, faulty draws {len(faults)}",
            flush=True,
        )
    return {
        "measured": "decays from the KVLCC2 simplified Ikeda prediction at 0.967 m/s, one component scaled, "
        "compared with the prediction at the decays' speed",
        "criterion": "every draw: lift in the prediction, no rig friction, the scaled part named first, "
        "factor within 20 %, gap shrinks >= 70 %; none scaled: nothing named",
        "passed": all(not r["faulty"] for r in rows),
        "cases": rows,
        "date": _now(),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=DRAWS)
    parser.add_argument("--set", choices=("all", "workflow", "prediction"), default="all")
    args = parser.parse_args()
    stored = json.loads(RESULT.read_text()) if RESULT.exists() else {}
    stored = stored.get("figures", stored)
    result = {key: stored.get(key) for key in ("passed", "cases", "prediction_sets", "workflow_date")}
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=os.cpu_count(), mp_context=context) as pool:
        if args.set in ("all", "workflow"):
            done = workflow_set(pool, args.draws)
            result.update(passed=done["passed"], cases=done["cases"], workflow_date=done["date"])
        if args.set in ("all", "prediction"):
            result["prediction_sets"] = prediction_set(pool, args.draws)
    write_result(
        "hidden_effects",
        "discrepancy workflow on three decays with one hidden effect of random size, and the prediction sets",
        counts={"draws": args.draws, "sets_run": args.set},
        figures=result,
        note=f"criterion: named first in >= {NAMED_SHARE:.0%} of draws; no faulty draw (a set not run keeps "
        "its stored figures and their own date)",
    )
    sets = [result["passed"], (result["prediction_sets"] or {}).get("passed")]
    return 0 if all(sets) else 1


if __name__ == "__main__":
    sys.exit(main())
