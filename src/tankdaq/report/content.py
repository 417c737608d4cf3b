"""What a report says, typed: sections of tables and figures, its warnings and its provenance.

The renderers (``report.html``, ``report.pdf``) and ``--json`` read only a ``ReportContent``, so they
hold the same numbers: every number is rounded here, once, to ``SIGNIFICANT`` digits (``rounded``), and
shown by ``cell_text`` with exactly those digits. An interval says what it is (``Interval``: its
coverage and its kind, ``± 95 % (fit)``) wherever it is shown.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd

#: Significant digits of every number a report shows (far finer than any fit's interval).
SIGNIFICANT = 6
#: A cell: a number, a word, or nothing (NaN, not known: shown as ``NOT_KNOWN``).
Cell = float | int | str | None
NOT_KNOWN = "–"


class Coverage(Enum):
    """How much of the distribution an interval covers."""

    P95 = "95 %"
    SIGMA1 = "1σ"


class IntervalKind(Enum):
    """Where an interval comes from: the fit's own covariance, or an expanded uncertainty (k = 2)."""

    FIT = "fit"
    EXPANDED = "expanded"


@dataclass(frozen=True)
class Interval:
    """An interval's coverage and kind; ``label`` is how every table and figure says it."""

    coverage: Coverage
    kind: IntervalKind

    @property
    def short(self) -> str:
        """``95 % (fit)``: the coverage and kind, as a bound's column names them."""
        return f"{self.coverage.value} ({self.kind.value})"

    @property
    def label(self) -> str:
        """``± 95 % (fit)``: as every table and figure says it."""
        return f"± {self.short}"


FIT_SIGMA = Interval(Coverage.SIGMA1, IntervalKind.FIT)
FIT_95 = Interval(Coverage.P95, IntervalKind.FIT)


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
class Table:
    """A titled table: ``columns`` (units in the names), ``rows`` of rounded cells, a ``caption``, and
    the ``intervals`` its columns hold (column -> ``Interval``). ``key`` names it in the JSON and the
    HTML (``data-key``), unique in a report."""

    key: str
    title: str
    columns: list[str]
    rows: list[list[Any]]  # each cell made a ``Cell`` (``rounded``) when the table is made
    caption: str = ""
    intervals: Mapping[str, Interval] = field(default_factory=dict)

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
        return interval.label if interval is not None and interval.short not in column else ""

    @classmethod
    def from_frame(
        cls,
        key: str,
        title: str,
        frame: pd.DataFrame,
        caption: str = "",
        intervals: Mapping[str, Interval] | None = None,
    ) -> Table:
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
            "intervals": {column: interval.label for column, interval in self.intervals.items()},
            "rows": self.rows,
        }


@dataclass(frozen=True)
class Figure:
    """A figure as PNG bytes, its caption saying every interval it draws (``intervals``)."""

    key: str
    title: str
    png: bytes = field(repr=False)
    caption: str = ""
    intervals: Sequence[Interval] = ()

    def document(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "title": self.title,
            "caption": self.caption,
            "intervals": [i.label for i in self.intervals],
        }


@dataclass(frozen=True)
class Section:
    """A part of the report: its tables, figures and notes (lines that stand beside the numbers, such
    as a condition's warnings), in that order."""

    key: str
    title: str
    tables: Sequence[Table] = ()
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
    def tables(self) -> list[Table]:
        return [table for section in self.sections for table in section.tables]

    def document(self, made: bool = True) -> dict[str, Any]:
        """What ``tankdaq report --json`` prints: the numbers the HTML and the PDF hold."""
        document: dict[str, Any] = {
            "title": self.title,
            "sections": [s.document() for s in self.sections],
            "warnings": list(self.warnings),
        }
        return {"made_utc": self.made_utc, **document} if made else document
