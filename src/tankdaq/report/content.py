"""What a report says, typed: sections of tables and figures, its warnings and its provenance.

The renderers (``report.html``, ``report.pdf``) and ``--json`` read only a ``ReportContent``, so they
hold the same numbers: every number is rounded here, once, to ``SIGNIFICANT`` digits (``rounded``), and
shown by ``cell_text`` with exactly those digits. An interval says what it is (``IntervalLabel``: its
coverage and its kind, ``± (95 %, fit)``: ``ident.interval_labels``) wherever it is shown.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..ident.interval_labels import IntervalLabel

if TYPE_CHECKING:
    import pandas as pd

#: Significant digits of every number a report shows (far finer than any fit's interval).
SIGNIFICANT = 6
#: A cell: a number, a word, or nothing (NaN, not known: shown as ``NOT_KNOWN``).
Cell = float | int | str | None
NOT_KNOWN = "–"


def rounded(value: object) -> Cell:
    """A cell as the report holds it: a real number to ``SIGNIFICANT`` digits (NaN and infinities:
    None), an integer as it is, anything else as text."""
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        number = float(value)
        return float(f"{number:.{SIGNIFICANT}g}") if math.isfinite(number) else None
    return str(value)


def cell_text(value: Cell) -> str:
    """A cell as the HTML and the PDF print it: the rounded number's digits, nothing else."""
    if value is None:
        return NOT_KNOWN
    if isinstance(value, float):
        return f"{value:.{SIGNIFICANT}g}"
    return str(value)


@dataclass(frozen=True)
class ReportTable:
    """A titled table: ``columns`` (units in the names), ``rows`` of rounded cells, a ``caption``, and
    the ``intervals`` its columns hold (column -> ``IntervalLabel``). ``key`` names it in the JSON and the
    HTML (``data-key``), unique in a report."""

    key: str
    title: str
    columns: list[str]
    rows: list[list[Any]]  # each cell made a ``Cell`` (``rounded``) when the table is made
    caption: str = ""
    intervals: Mapping[str, IntervalLabel] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "rows", [[rounded(cell) for cell in row] for row in self.rows])
        for row in self.rows:
            if len(row) != len(self.columns):
                raise ValueError(
                    f"table {self.key}: a row of {len(row)} cells under {len(self.columns)} columns"
                )
        unknown = set(self.intervals) - set(self.columns)
        if unknown:
            raise ValueError(f"table {self.key}: intervals of no column {sorted(unknown)}")

    def interval_said(self, column: str) -> str:
        """The interval ``column`` holds, for its header, where its name does not say it already."""
        interval = self.intervals.get(column)
        return interval.text if interval is not None and interval.said not in column else ""

    @classmethod
    def from_frame(
        cls,
        key: str,
        title: str,
        frame: pd.DataFrame,
        caption: str = "",
        intervals: Mapping[str, IntervalLabel] | None = None,
    ) -> ReportTable:
        """A DataFrame as a report table (its columns and rows as they are; the index is dropped)."""
        rows = [list(row) for row in frame.itertuples(index=False, name=None)]
        return cls(key, title, [str(c) for c in frame.columns], rows, caption, dict(intervals or {}))

    def to_frame(self) -> pd.DataFrame:
        import pandas as pd

        return pd.DataFrame(self.rows, columns=self.columns)

    def document(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "title": self.title,
            "caption": self.caption,
            "columns": self.columns,
            "intervals": {column: interval.text for column, interval in self.intervals.items()},
            "rows": self.rows,
        }


@dataclass(frozen=True)
class Figure:
    """A figure as PNG bytes, its caption saying every interval it draws (``intervals``)."""

    key: str
    title: str
    png: bytes = field(repr=False)
    caption: str = ""
    intervals: Sequence[IntervalLabel] = ()

    def document(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "title": self.title,
            "caption": self.caption,
            "intervals": [i.text for i in self.intervals],
        }


@dataclass(frozen=True)
class Section:
    """A part of the report: its tables, figures and notes (lines that stand beside the numbers, such
    as a condition's warnings), in that order."""

    key: str
    title: str
    tables: Sequence[ReportTable] = ()
    figures: Sequence[Figure] = ()
    notes: Sequence[str] = ()

    def document(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "title": self.title,
            "tables": [t.document() for t in self.tables],
            "figures": [f.document() for f in self.figures],
            "notes": list(self.notes),
        }


@dataclass(frozen=True)
class ReportContent:
    """The whole report: its sections (the provenance last), every warning, and when it was made (the
    one thing a rerun on the same inputs may change: ``document(made=False)`` leaves it out)."""

    title: str
    sections: Sequence[Section]
    warnings: Sequence[str]
    made_utc: str

    def __post_init__(self) -> None:
        keys = [t.key for s in self.sections for t in s.tables] + [
            f.key for s in self.sections for f in s.figures
        ]
        twice = sorted({k for k in keys if keys.count(k) > 1})
        if twice:
            raise ValueError(f"report keys given twice: {twice}")

    @property
    def tables(self) -> list[ReportTable]:
        return [table for section in self.sections for table in section.tables]

    def document(self, made: bool = True) -> dict[str, Any]:
        """What ``tankdaq report --json`` prints: the numbers the HTML and the PDF hold."""
        document: dict[str, Any] = {
            "title": self.title,
            "sections": [s.document() for s in self.sections],
            "warnings": list(self.warnings),
        }
        return {"made_utc": self.made_utc, **document} if made else document
