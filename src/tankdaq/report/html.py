"""A report as one self-contained HTML file: the style inline, every figure a ``data:`` URI, no link
to anything outside it (a reviewer opens it offline, years later). Each table carries its key
(``data-key``) and each cell the text ``content.cell_text`` gives, the same numbers ``--json`` prints."""

from __future__ import annotations

import base64
from html import escape

from .content import ReportContent, ReportTable, Section, cell_text

STYLE = """
body { font-family: sans-serif; max-width: 72rem; margin: 2rem auto; padding: 0 1rem; color: #222; }
h1 { font-size: 1.6rem; } h2 { font-size: 1.3rem; border-bottom: 1px solid #ccc; } h3 { font-size: 1.05rem; }
table { border-collapse: collapse; margin: 0.5rem 0 0.3rem; font-size: 0.85rem; }
th, td { border: 1px solid #ccc; padding: 0.2rem 0.45rem; text-align: left; vertical-align: top; }
td.number { text-align: right; font-variant-numeric: tabular-nums; }
th { background: #f2f2f2; }
caption { caption-side: bottom; text-align: left; font-size: 0.8rem; color: #555; padding-top: 0.2rem; }
.interval { color: #555; font-weight: normal; font-size: 0.75rem; }
.warning { color: #a00; }
figure { margin: 1rem 0; } figure img { max-width: 100%; } figcaption { font-size: 0.8rem; color: #555; }
"""


def render_html(content: ReportContent) -> str:
    """The whole report as one HTML document (UTF-8)."""
    warnings = "".join(f'<li class="warning">{escape(line)}</li>' for line in content.warnings)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{escape(content.title)}</title><style>{STYLE}</style></head><body>",
        f"<h1>{escape(content.title)}</h1>",
        f'<p>made <time id="made-utc">{escape(content.made_utc)}</time> (UTC)</p>',
        '<section id="warnings"><h2>Warnings</h2>',
        f'<ul id="warning-list">{warnings}</ul>' if warnings else "<p>none</p>",
        "</section>",
        *(_section(section) for section in content.sections),
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"


def _section(section: Section) -> str:
    notes = "".join(
        f'<li class="{"warning" if note.startswith("warning:") else "note"}">{escape(note)}</li>'
        for note in section.notes
    )
    figures = "".join(
        f'<figure data-key="{escape(f.key)}"><img alt="{escape(f.title)}" '
        f'src="data:image/png;base64,{base64.b64encode(f.png).decode("ascii")}">'
        f"<figcaption>{escape(f.title)}. {escape(f.caption)}</figcaption></figure>"
        for f in section.figures
    )
    return (
        f'<section id="{escape(section.key)}"><h2>{escape(section.title)}</h2>'
        + "".join(_table(table) for table in section.tables)
        + (f"<ul>{notes}</ul>" if notes else "")
        + figures
        + "</section>"
    )


def _table(table: ReportTable) -> str:
    heads = "".join(
        f"<th>{escape(column)}"
        + (
            f' <span class="interval">[{escape(label)}]</span>'
            if (label := table.interval_said(column))
            else ""
        )
        + "</th>"
        for column in table.columns
    )
    rows = "".join(
        "<tr>"
        + "".join(f'<td class="{_kind(cell)}">{escape(cell_text(cell))}</td>' for cell in row)
        + "</tr>"
        for row in table.rows
    )
    caption = f"<caption>{escape(table.caption)}</caption>" if table.caption else ""
    return (
        f'<h3>{escape(table.title)}</h3><table data-key="{escape(table.key)}">{caption}'
        f"<thead><tr>{heads}</tr></thead><tbody>{rows}</tbody></table>"
    )


def _kind(cell: object) -> str:
    return "number" if isinstance(cell, int | float) else "text"
