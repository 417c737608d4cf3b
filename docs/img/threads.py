"""Draws docs/img/threads.svg: the processes and threads one live decay crosses (docs/architecture.md).

This file is the picture's source: edit the boxes and arrows below, run
``.venv/bin/python docs/img/threads.py`` and commit both files. The same source gives the same bytes
(fixed ids, no date), and the SVG says which source drew it (its SHA-256: a test checks it is this file's).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

OUT = Path(__file__).with_suffix(".svg")

PROCESS: dict[str, Any] = {"facecolor": "#f4f6fb", "edgecolor": "#2b3a67", "linewidth": 2.0}
THREAD: dict[str, Any] = {"facecolor": "#ffffff", "edgecolor": "#4a6fa5", "linewidth": 1.1}
FILE: dict[str, Any] = {"facecolor": "#eeeeee", "edgecolor": "#777777", "linewidth": 1.0}
DEVICE: dict[str, Any] = {"facecolor": "#fff4e0", "edgecolor": "#b07a1c", "linewidth": 1.4}

#: (x0, y0, x1, y1), style, title, body lines, title size; the axes run 0-100 across and 0-65 up.
BOXES = [
    ((1, 49, 17, 61), DEVICE, "MTi-G", (
        "on a serial port, or the", "simulated one on a pty", "(--port sim: device/simulator/)"), 9.5),
    ((1, 21, 17, 42), PROCESS, "reader process", (
        "device/read_process.py", "python -I -S: stdlib only,", "real-time priority if allowed", "",
        "reads the port every 20 ms,", "stamps host time; lives while", "the device streams"), 9.5),
    ((22, 45, 39, 59), THREAD, "tankdaq-read", (
        "acquire/read_thread.py", "decodes the reads: bytes ->", "frames -> samples", "(device/decoding.py,",
        "xsens/stream_decoder.py)"), 9.5),
    ((43, 40, 67, 59), THREAD, "pipeline thread", (
        "the thread that calls run(): the main", "thread of record and of session",
        "acquire/pipeline.py: release, settle", "acquire/sinks.py, in this order:",
        "  identifier  (submits samples, takes fits)", "  file  (store/writer.py, one MCAP a decay)",
        "  view  (queues blocks, fits, events)", "  listeners: printer, catalogue sink"), 9.5),
    ((71, 46, 97, 59), THREAD, "tankdaq-live-fit", (
        "live/worker.py (BackgroundFit)", "refits at every half-cycle, warm-started,",
        "coalesced on the newest samples;", "the final fit at settle; each under a budget"), 9.5),
    ((22, 22, 39, 36), THREAD, "tankdaq-ask", (
        "acquire/streaming.py", "guided session only: waits for", "the operator's answer while",
        "the pipeline thread reads on"), 9.5),
    ((43, 22, 55, 36), THREAD, "tankdaq-view", (
        "viz/view_feed.py", "sends view jobs to the", "view process; drops", "blocks and refits when",
        "behind, never a final fit"), 9.5),
    ((57, 22, 67, 36), THREAD, "tankdaq-view-notes", (
        "viz/view_process.py", "hears the view's", "notes (one line", "each)"), 7.4),
    ((75, 22, 97, 36), THREAD, "tankdaq-catalogue", (
        "catalogue/hooks.py (CatalogueWriter)", "after the file closed: its row read back",
        "from the file, written in one transaction;", "locked or down costs a line, never a file"), 9.5),
    ((27, 2, 52, 16), PROCESS, "view process", (
        "python -m tankdaq.viz.view_process", "LiveView and its own tankdaq-view thread",
        "log to rerun; a fresh process every", "100 decays (what rerun keeps is freed)"), 9.5),
    ((1, 2, 23, 16), PROCESS, "rerun viewer", (
        "a window (--viewer spawn), or the", "web viewer's server for a tablet",
        "(--viewer web); outlives tankdaq"), 9.5),
    ((56, 4, 67, 14), FILE, ".rrd", ("one per decay,", "the view as seen"), 9.5),
    ((70, 4, 82, 14), FILE, ".mcap", ("one per decay:", "raw bytes, samples,", "events, fits"), 9.5),
    ((85, 4, 98, 14), FILE, "catalogue", ("SQLite or", "PostgreSQL:", "one row a decay"), 9.5),
]  # fmt: skip

#: start, end, label, where along the arrow the label sits (0-1), its offset (dx, dy), dashed.
ARROWS = [
    ((9, 49), (9, 42), "bytes", 0.5, (2.2, 0), False),
    ((17, 31), (26, 45), "(stamps, bytes)\nover a pipe", 0.55, (3.2, 0), False),
    ((39, 52), (43, 52), "blocks", 0.5, (0, 1.4), False),
    ((67, 54), (71, 54), "samples", 0.5, (0, 1.4), False),
    ((71, 49), (67, 49), "fits", 0.5, (0, -1.4), False),
    ((39, 30), (45, 40), "answer", 0.4, (-1.6, 0), False),
    ((49.5, 40), (49.5, 36), "", 0.5, (0, 0), False),
    ((67, 43), (82, 36), "settled decay,\nfile closed", 0.55, (0, 1.8), False),
    ((47, 22), (43, 16), "socket", 0.25, (-3.0, 0), False),
    ((52, 12), (59, 22), "notes", 0.45, (2.2, 0), True),
    ((27, 9), (23, 9), "gRPC", 0.5, (0, 1.6), False),
    ((52, 6), (56, 6), "", 0.5, (0, 0), False),
    ((66.6, 40.2), (76.5, 14), "write", 0.62, (-1.8, 0), False),
    ((90, 22), (90, 14), "rows", 0.5, (2.0, 0), False),
]

RECORDER = (
    "recorder process: tankdaq record, tankdaq session "
    + "(tankdaq replay: a file in place of the two on the left)"
)
LEGEND = (
    "thick box: a process; thin box: a thread; grey: a file. "
    "Names are the threads' names (threading.Thread name=)."
)


def box(
    ax: Axes,
    corners: tuple[float, ...],
    style: dict[str, Any],
    title: str,
    body: tuple[str, ...],
    size: float,
) -> None:
    """A rounded box, its title in bold monospace at the top and its body under it."""
    x0, y0, x1, y1 = corners
    ax.add_patch(
        FancyBboxPatch((x0, y0), x1 - x0, y1 - y0, boxstyle="round,pad=0,rounding_size=0.8", **style)
    )
    family = "sans-serif" if style is DEVICE else "monospace"
    ax.text(x0 + 0.8, y1 - 0.9, title, va="top", fontsize=size, weight="bold", family=family)
    ax.text(x0 + 0.8, y1 - 3.6, "\n".join(body), va="top", fontsize=7.6, linespacing=1.35)


def arrow(ax: Axes, start: tuple[float, float], end: tuple[float, float], label: str, where: float,
          offset: tuple[float, float], dashed: bool) -> None:  # fmt: skip
    line = "--" if dashed else "-"
    ax.add_patch(
        FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=11, color="#333", linestyle=line)
    )
    if label:
        x = start[0] + (end[0] - start[0]) * where + offset[0]
        y = start[1] + (end[1] - start[1]) * where + offset[1]
        blank = {"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none"}
        ax.text(x, y, label, fontsize=7.2, style="italic", ha="center", va="center", bbox=blank)


def draw() -> Figure:
    fig = plt.figure(figsize=(13.0, 8.4))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 65)
    ax.axis("off")
    ax.add_patch(FancyBboxPatch((20, 19), 79, 45, boxstyle="round,pad=0,rounding_size=1.2", **PROCESS))
    ax.text(21, 63.2, RECORDER, va="top", fontsize=9.5, weight="bold")
    for corners, style, title, body, size in BOXES:
        box(ax, corners, style, title, body, size)
    for start, end, label, where, offset, dashed in ARROWS:
        arrow(ax, start, end, label, where, offset, dashed)
    ax.text(41, 48.6, "queue:\nnever\ndrops", fontsize=6.8, ha="center", va="top", style="italic")
    ax.text(1, 0.6, LEGEND, fontsize=7.2, color="#444444")
    return fig


def main() -> None:
    matplotlib.rcParams["svg.hashsalt"] = "threads.svg"  # the same ids every run
    source = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()
    fig = draw()
    fig.savefig(OUT, format="svg", metadata={"Date": None, "Source": f"docs/img/threads.py sha256 {source}"})
    plt.close(fig)
    print(OUT)


if __name__ == "__main__":
    main()
