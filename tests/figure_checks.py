"""Checks on matplotlib figures that tests share: no two pieces of text drawn over each other."""

from __future__ import annotations

from itertools import combinations

from matplotlib.figure import Figure
from matplotlib.text import Text


def drawn_texts(fig: Figure) -> list[tuple[str, object]]:
    """Every text the figure draws (titles, labels, tick labels in view, legend entries) with its
    bounding box in display pixels, after a draw (the layout engine places them then). An axis keeps
    tick objects outside its view limits that are not drawn: those are left out."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    ticks: set[int] = set()
    texts: list[Text] = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            low, high = sorted(axis.get_view_interval())
            margin = 1e-9 * (high - low)
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                labels = (tick.label1, tick.label2)
                ticks.update(id(label) for label in labels)
                if low - margin <= tick.get_loc() <= high + margin:
                    texts += labels
    texts += [t for t in fig.findobj(Text) if id(t) not in ticks]
    return [
        (t.get_text(), t.get_window_extent(renderer))
        for t in texts
        if t.get_visible() and t.get_text().strip() and t.get_alpha() != 0
    ]


def overlapping_texts(fig: Figure, tolerance_px: float = 0.5) -> list[tuple[str, str]]:
    """Pairs of texts whose boxes overlap by more than ``tolerance_px`` in both directions."""
    pairs = []
    for (a, box_a), (b, box_b) in combinations(drawn_texts(fig), 2):
        width = min(box_a.x1, box_b.x1) - max(box_a.x0, box_b.x0)  # type: ignore[attr-defined]
        height = min(box_a.y1, box_b.y1) - max(box_a.y0, box_b.y0)  # type: ignore[attr-defined]
        if width > tolerance_px and height > tolerance_px:
            pairs.append((a, b))
    return pairs
