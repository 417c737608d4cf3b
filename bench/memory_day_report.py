"""What ``bench_memory_day.py`` prints and writes from its children's JSON lines: RSS at start, after the
warm-up and at the end, its growth per simulated hour, and each part of the memory state."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def read_rows(log: Path) -> list[dict[str, object]]:
    return [json.loads(line) for line in log.read_text().splitlines() if line.startswith("{")]


def describe(tree: str, rows: list[dict[str, object]], warmup: int, run_s: float) -> list[str]:
    """RSS at start, after the warm-up and at the end, and the growth per simulated hour after it."""
    per_decay = [r for r in rows if "rss_kb" in r and "decay" in r]
    summary = next((r for r in rows if "gaps" in r), {})
    if len(per_decay) <= warmup + 2:
        return [f"{tree}: only {len(per_decay) - 1} decays recorded ({summary})"]
    decay = np.array([r["decay"] for r in per_decay], dtype=float)
    rss_mb = np.array([r["rss_kb"] for r in per_decay], dtype=float) / 1024
    hours = decay * run_s / 3600
    after = decay >= warmup
    slope_mb_h = float(np.polyfit(hours[after], rss_mb[after], 1)[0])
    warm, span_h = float(rss_mb[after][0]), float(hours[-1] - hours[after][0])
    wall_min = float(per_decay[-1]["wall_s"]) / 60  # type: ignore[arg-type]
    lines = [
        f"{tree}: {int(decay[-1])} decays = {hours[-1]:.2f} simulated h in {wall_min:.1f} min wall; samples "
        f"{summary.get('samples')}, gaps {summary.get('gaps')}, bad frames {summary.get('bad_frames')}",
        f"  RSS start {rss_mb[0]:.1f} MB, after warm-up ({warmup} decays, {hours[after][0]:.2f} h) "
        f"{warm:.1f} MB, end {rss_mb[-1]:.1f} MB: {rss_mb[-1] - warm:+.1f} MB in the {span_h:.2f} h after it "
        f"({(rss_mb[-1] - warm) / span_h:+.2f} MB/h; least-squares slope {slope_mb_h:+.2f} MB/h), "
        f"peak {rss_mb.max():.1f} MB",
    ]
    first_hour = after & (hours < hours[after][0] + 1)
    last_hour = after & (hours >= hours[-1] - 1)
    if span_h >= 2:  # one sample scatters by +-3 MB between decays: an hour's median is the level
        level = float(np.median(rss_mb[last_hour]) - np.median(rss_mb[first_hour]))
        lines.append(
            f"  median RSS of the last simulated hour against the first after the warm-up: {level:+.1f} MB"
        )
    late = hours >= hours[after][0] + span_h / 2  # the second half after the warm-up: does it plateau?
    if late.sum() > 3:
        late_slope = float(np.polyfit(hours[late], rss_mb[late], 1)[0])
        lines.append(
            f"  least-squares slope over the last {hours[-1] - hours[late][0]:.2f} h: {late_slope:+.2f} MB/h"
        )
    lines += describe_parts(rows, warmup, run_s)
    return lines + [f"    {line}" for line in rows[-1].get("tracemalloc", [])]  # type: ignore[union-attr]


def describe_parts(rows: list[dict[str, object]], warmup: int, run_s: float) -> list[str]:
    """Each part of ``memory_state`` at the releases after the warm-up: first, last, least-squares slope."""
    states = [r for r in rows if "before_decay" in r and int(r["before_decay"]) > warmup]  # type: ignore[call-overload]
    if len(states) < 3:
        return []
    hours = np.array([r["before_decay"] for r in states], dtype=float) * run_s / 3600
    lines = ["  at each release after the warm-up (first -> last, least-squares slope per simulated hour):"]
    for key in states[0]:
        if key == "before_decay":
            continue
        values = np.array([r.get(key, np.nan) for r in states], dtype=float)
        scale, unit = (1 / 1024, "MB") if key.endswith("_kb") else (1, "")
        slope = float(np.polyfit(hours, values * scale, 1)[0])
        first, last = values[0] * scale, values[-1] * scale
        lines.append(f"    {key:15s} {first:10.1f} -> {last:10.1f} {unit:2s} ({slope:+.2f}/h)")
    hour = np.floor(hours).astype(int)
    for key, what in (("rss_kb", "RSS"), ("own_rss_kb", "the recorder's own RSS (its view's apart)")):
        mb = np.array([r[key] for r in states], dtype=float) / 1024
        medians = [f"{h}: {np.median(mb[hour == h]):.1f}" for h in np.unique(hour)]
        lines.append(f"  {what} at the releases, median of each simulated hour (MB): {', '.join(medians)}")
    return lines


def figures(rows: list[dict[str, object]], warmup: int, run_s: float) -> dict[str, float]:
    """The figures ``describe`` states first, as numbers for bench/results/memory_day.json."""
    per_decay = [r for r in rows if "rss_kb" in r and "decay" in r]
    if len(per_decay) <= warmup + 2:
        return {"decays": len(per_decay) - 1}
    decay = np.array([r["decay"] for r in per_decay], dtype=float)
    rss_mb = np.array([r["rss_kb"] for r in per_decay], dtype=float) / 1024
    hours = decay * run_s / 3600
    after = decay >= warmup
    warm, span_h = float(rss_mb[after][0]), float(hours[-1] - hours[after][0])
    return {
        "decays": int(decay[-1]),
        "simulated_h": float(hours[-1]),
        "wall_min": float(per_decay[-1]["wall_s"]) / 60,  # type: ignore[arg-type]
        "rss_start_mb": float(rss_mb[0]),
        "rss_after_warmup_mb": warm,
        "rss_end_mb": float(rss_mb[-1]),
        "rss_peak_mb": float(rss_mb.max()),
        "growth_after_warmup_mb_per_h": (float(rss_mb[-1]) - warm) / span_h,
        "slope_after_warmup_mb_per_h": float(np.polyfit(hours[after], rss_mb[after], 1)[0]),
    }
