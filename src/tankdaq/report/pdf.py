"""A report as a PDF, made with matplotlib (no other dependency): text pages for the tables, notes and
warnings (a monospaced font, tables wider than a page split into column groups that repeat the first
column, long cells wrapped), then one page per figure with its caption. Fonts are embedded as TrueType,
so a PDF reader (and ``pdftotext``) reads the same numbers the HTML shows."""

from __future__ import annotations

import datetime
import io
import textwrap
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib as mpl
import numpy as np
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure as MplFigure
from PIL import Image

from ..store.safe_write import new_path
from .content import Figure, ReportContent, ReportTable, cell_text

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

#: A4 landscape (inches), its margin, and the text: size (pt), line height, characters a line holds.
PAGE_IN, MARGIN_IN = (11.69, 8.27), 0.5
FONT_PT, LINE_PT = 7.0, 9.5
LINE_CHARS = int((PAGE_IN[0] - 2 * MARGIN_IN) * 72 / (FONT_PT * 0.61))
PAGE_LINES = int((PAGE_IN[1] - 2 * MARGIN_IN) * 72 / LINE_PT)
#: The widest a cell is before it wraps onto more lines.
CELL_CHARS = 96
STYLE: dict[RcKeyType, Any] = {"pdf.fonttype": 42, "font.family": "DejaVu Sans Mono", "font.size": FONT_PT}
#: A line of a text page: its text and whether it is a heading (bold) or a warning (red).
Line = tuple[str, str]


def write_pdf(content: ReportContent, path: Path) -> Path:
    """The report as a new PDF at ``path`` (``store.safe_write``: never over a file)."""
    made = datetime.datetime.fromisoformat(content.made_utc)
    metadata = {"Title": content.title, "Creator": "tankdaq report", "CreationDate": made}
    with mpl.rc_context(STYLE), new_path(path) as temporary, PdfPages(temporary, metadata=metadata) as pages:
        for lines in _paginated(list(_text_lines(content))):
            pages.savefig(_text_page(lines))
        for section in content.sections:
            for figure in section.figures:
                pages.savefig(_figure_page(section.title, figure))
    return path


def _text_lines(content: ReportContent) -> Iterator[Line]:
    yield content.title, "title"
    yield f"made {content.made_utc} (UTC)", "text"
    yield "", "text"
    yield "Warnings", "heading"
    for line in content.warnings or ["none"]:
        yield from _wrapped(line, "warning" if content.warnings else "text")
    for section in content.sections:
        yield "", "text"
        yield section.title, "heading"
        for table in section.tables:
            yield from _table_lines(table)
        for note in section.notes:
            yield from _wrapped(note, "warning" if note.startswith("warning:") else "text")


def _wrapped(text: str, style: str) -> Iterator[Line]:
    for line in textwrap.wrap(text, LINE_CHARS, subsequent_indent="  ") or [""]:
        yield line, style


def _table_lines(table: ReportTable) -> Iterator[Line]:
    """A table as text: its title, its columns in groups that fit a line, each cell wrapped."""
    yield "", "text"
    yield table.title, "subheading"
    heads = [
        column + (f" [{label}]" if (label := table.interval_said(column)) else "") for column in table.columns
    ]
    cells = [[textwrap.wrap(cell_text(cell), CELL_CHARS) or [""] for cell in row] for row in table.rows]
    widths = [
        max([len(heads[c])] + [len(part) for row in cells for part in row[c]]) for c in range(len(heads))
    ]
    for group in _column_groups(widths):
        yield "  ".join(heads[c].ljust(widths[c]) for c in group), "text"
        yield "  ".join("-" * widths[c] for c in group), "text"
        for row in cells:
            for k in range(max(len(row[c]) for c in group)):
                parts = [(row[c][k] if k < len(row[c]) else "").ljust(widths[c]) for c in group]
                yield "  ".join(parts).rstrip(), "text"
    if table.caption:
        yield from _wrapped(table.caption, "caption")


def _column_groups(widths: Sequence[int]) -> list[list[int]]:
    """Columns in groups whose line fits the page, each after the first repeating column 0."""
    groups: list[list[int]] = [[0]]
    for c in range(1, len(widths)):
        if sum(widths[i] + 2 for i in groups[-1]) + widths[c] > LINE_CHARS and len(groups[-1]) > 1:
            groups.append([0])
        groups[-1].append(c)
    return groups


def _paginated(lines: list[Line]) -> Iterator[list[Line]]:
    for start in range(0, len(lines), PAGE_LINES):
        yield lines[start : start + PAGE_LINES]


_LOOK = {
    "title": {"size": 12.0, "weight": "bold"},
    "heading": {"size": 9.5, "weight": "bold"},
    "subheading": {"weight": "bold"},
    "warning": {"color": "#a00000"},
    "caption": {"color": "#555555"},
    "text": {},
}


def _text_page(lines: list[Line]) -> MplFigure:
    figure = MplFigure(figsize=PAGE_IN)
    top = 1.0 - MARGIN_IN / PAGE_IN[1]
    step = LINE_PT / 72 / PAGE_IN[1]
    for n, (text, style) in enumerate(lines):
        if text:
            figure.text(MARGIN_IN / PAGE_IN[0], top - n * step, text, va="top", **_LOOK[style])  # type: ignore[arg-type]
    return figure


def _figure_page(section: str, figure: Figure) -> MplFigure:
    """One figure on a page: its section and title above, the image, its caption below."""
    page = MplFigure(figsize=PAGE_IN)
    left = MARGIN_IN / PAGE_IN[0]
    page.text(left, 1.0 - MARGIN_IN / PAGE_IN[1], f"{section}: {figure.title}", va="top", **_LOOK["heading"])  # type: ignore[arg-type]
    # the PNG's bytes as they are (uint8): matplotlib's imread made floats that imshow turned back
    with Image.open(io.BytesIO(figure.png)) as png:
        image = np.asarray(png)
    axes = page.add_axes((left, 0.12, 1.0 - 2 * left, 0.78))
    # "none": the PNG's own pixels go into the PDF, scaled by the reader (the figure the HTML shows);
    # resampled here they were a third larger and blurred, and cost a tenth of the PDF's time
    axes.imshow(image, interpolation="none")
    axes.set_axis_off()
    for n, line in enumerate(textwrap.wrap(figure.caption, LINE_CHARS)):
        page.text(left, 0.09 - n * LINE_PT / 72 / PAGE_IN[1], line, va="top", **_LOOK["caption"])  # type: ignore[arg-type]
    return page
