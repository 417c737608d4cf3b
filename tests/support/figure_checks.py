"""Checks on matplotlib figures that tests share: no two pieces of text drawn over each other, none cut
off at the figure's edge, no legend on a panel's data (issue 23: every report figure fit to hand on)."""

from __future__ import annotations

from itertools import combinations

from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.text import Text


def drawn_texts(fig: Figure) -> list[tuple[str, object]]:
    """Every text the figure draws (titles, labels, tick labels in view, legend entries) with its
    bounding box in display pixels, after a draw (the layout engine places them then). An axis keeps
    tick objects outside its view limits that are not drawn: those are left out."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    ticks: set[int] = set()
    texts: list[Text] = []
    for ax in [*fig.axes, *(child for parent in fig.axes for child in parent.child_axes)]:  # + secondary axes
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
    return _overlapping(drawn_texts(fig), tolerance_px)


def _overlapping(texts: list[tuple[str, object]], tolerance_px: float) -> list[tuple[str, str]]:
    pairs = []
    for (a, box_a), (b, box_b) in combinations(texts, 2):
        width = min(box_a.x1, box_b.x1) - max(box_a.x0, box_b.x0)  # type: ignore[attr-defined]
        height = min(box_a.y1, box_b.y1) - max(box_a.y0, box_b.y0)  # type: ignore[attr-defined]
        if width > tolerance_px and height > tolerance_px:
            pairs.append((a, b))
    return pairs


def clipped_texts(fig: Figure, tolerance_px: float = 0.5) -> list[str]:
    """Texts that reach outside the figure (cut off in the PNG)."""
    return _clipped(fig, drawn_texts(fig), tolerance_px)


def _clipped(fig: Figure, texts: list[tuple[str, object]], tolerance_px: float) -> list[str]:
    box = fig.bbox
    return [
        text
        for text, extent in texts
        if extent.x0 < box.x0 - tolerance_px  # type: ignore[attr-defined]
        or extent.y0 < box.y0 - tolerance_px  # type: ignore[attr-defined]
        or extent.x1 > box.x1 + tolerance_px  # type: ignore[attr-defined]
        or extent.y1 > box.y1 + tolerance_px  # type: ignore[attr-defined]
    ]


def legends_on_axes(fig: Figure, drawn: bool = False) -> list[str]:
    """Legends drawn over a panel's data area (their entries' texts): a legend belongs beside the data.
    ``drawn``: the figure was just drawn (its layout is placed)."""
    if not drawn:
        fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    found = []
    for legend in (legend for legend in fig.findobj(Legend) if legend.get_visible()):
        box = legend.get_window_extent(renderer)
        for ax in fig.axes:
            panel = ax.get_window_extent(renderer)
            width = min(box.x1, panel.x1) - max(box.x0, panel.x0)
            height = min(box.y1, panel.y1) - max(box.y0, panel.y0)
            if width > 0.5 and height > 0.5:
                found.append(" ".join(t.get_text() for t in legend.get_texts()))
    return found


def layout_problems(fig: Figure, tolerance_px: float = 0.5) -> dict[str, list]:
    """Everything that makes a figure unfit to hand on, by kind (one draw); empty lists when it is fit."""
    texts = drawn_texts(fig)
    return {
        "overlapping": _overlapping(texts, tolerance_px),
        "clipped": _clipped(fig, texts, tolerance_px),
        "legend on data": legends_on_axes(fig, drawn=True),
    }


def assert_fit_to_hand_on(fig: Figure, name: str = "figure") -> None:
    """No overlapping or clipped text, no legend on a panel."""
    problems = {kind: found for kind, found in layout_problems(fig).items() if found}
    assert not problems, f"{name}: {problems}"
