"""What an interval is, said once: its coverage (1σ, 95 %, k = 2, range) and its kind (fit, bootstrap,
repeats, initial angles, standard, expanded).

A reader misjudges an uncertainty by 2x when a figure's 95 % bars stand beside a table's "± 1σ" and
neither says which. So every ± in a table, every interval column of a CSV, JSON object or DataFrame,
and every bar or band in a figure is labelled from an ``IntervalLabel`` here, in one form:
``<symbol> (<coverage>, <kind>)``; e.g. ``± (1σ, fit)``, ``± (95 %, fit)``, ``± (range, initial
angles)``, ``u (1σ, standard)``, ``U (k=2, ≈95 %, expanded)`` (docs/intervals.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Coverage(Enum):
    """How much of the spread an interval covers."""

    ONE_SIGMA = "1σ"
    P95 = "95 %"
    K2 = "k=2, ≈95 %"
    RANGE = "range"

    @property
    def factor(self) -> float | None:
        """Half-width per standard deviation (normal; None for a range, which is no multiple of one)."""
        return _FACTORS[self]

    @property
    def suffix(self) -> str:
        """The column suffix of a half-width of this coverage (``b1_std``, ``b_eq_ci95``, ``T0_U``)."""
        return _SUFFIXES[self]


_FACTORS = {Coverage.ONE_SIGMA: 1.0, Coverage.P95: 1.96, Coverage.K2: 2.0, Coverage.RANGE: None}
_SUFFIXES = {Coverage.ONE_SIGMA: "std", Coverage.P95: "ci95", Coverage.K2: "U", Coverage.RANGE: "half_range"}


class IntervalSource(Enum):
    """Where an interval comes from."""

    FIT = "fit"
    BOOTSTRAP = "bootstrap"
    REPEATS = "repeats"
    SCATTER = "scatter of repeats"
    ANGLES = "initial angles"
    STANDARD = "standard"
    EXPANDED = "expanded"

    @property
    def description(self) -> str:
        """One sentence for legends of tables and docs/intervals.md."""
        return _DESCRIPTIONS[self]


_DESCRIPTIONS = {
    IntervalSource.FIT: "the fit's own covariance (through the delta method for derived quantities)",
    IntervalSource.BOOTSTRAP: "a moving-block bootstrap of the fit's residuals",
    IntervalSource.REPEATS: "repeat decays of one condition fitted one by one: the standard deviation of "
    "their mean (GUM Type A; 95 % with Student's t, n - 1)",
    IntervalSource.SCATTER: "repeat decays fitted one by one: their sample standard deviation (one decay's "
    "scatter, not the mean's uncertainty)",
    IntervalSource.ANGLES: "the fits at different initial angles of one hull, axis and draft: the standard "
    "deviation of their mean, or half their range",
    IntervalSource.STANDARD: "the combined standard uncertainty of the budget (GUM)",
    IntervalSource.EXPANDED: "the expanded uncertainty of the budget, k = 2 (GUM)",
}


@dataclass(frozen=True)
class IntervalLabel:
    """An interval's coverage and kind, and the symbol it is written with (± for a half-width)."""

    coverage: Coverage
    kind: IntervalSource
    symbol: str = "±"

    @property
    def text(self) -> str:
        """``± (95 %, fit)``: what a legend, a table's header or a caption says."""
        return f"{self.symbol} {self.said}"

    @property
    def said(self) -> str:
        """``(95 %, fit)``: the coverage and kind alone, as a bound's column names them (``... low``)."""
        return f"({self.coverage.value}, {self.kind.value})"

    def __str__(self) -> str:
        return self.text

    def half_width(self, std: float) -> float:
        """The half-width of this interval for a standard deviation ``std``."""
        factor = self.coverage.factor
        if factor is None:
            raise ValueError(f"{self.text} is a range, not a multiple of a standard deviation")
        return factor * std

    def as_dict(self) -> dict[str, str]:
        """For ``--json``: coverage, kind and the label."""
        return {"coverage": self.coverage.value, "kind": self.kind.value, "label": self.text}


FIT_STD = IntervalLabel(Coverage.ONE_SIGMA, IntervalSource.FIT)
FIT_95 = IntervalLabel(Coverage.P95, IntervalSource.FIT)
BOOTSTRAP_STD = IntervalLabel(Coverage.ONE_SIGMA, IntervalSource.BOOTSTRAP)
BOOTSTRAP_95 = IntervalLabel(Coverage.P95, IntervalSource.BOOTSTRAP)
REPEATS_STD = IntervalLabel(Coverage.ONE_SIGMA, IntervalSource.REPEATS)
REPEATS_95 = IntervalLabel(Coverage.P95, IntervalSource.REPEATS)
SCATTER_STD = IntervalLabel(Coverage.ONE_SIGMA, IntervalSource.SCATTER)
ANGLES_STD = IntervalLabel(Coverage.ONE_SIGMA, IntervalSource.ANGLES)
ANGLES_RANGE = IntervalLabel(Coverage.RANGE, IntervalSource.ANGLES)
#: The uncertainty budget's (``ident.budget``): the combined standard and the expanded uncertainty.
STANDARD_U = IntervalLabel(Coverage.ONE_SIGMA, IntervalSource.STANDARD, "u")
EXPANDED_U = IntervalLabel(Coverage.K2, IntervalSource.EXPANDED, "U")

ALL_LABELS = (
    FIT_STD, FIT_95, BOOTSTRAP_STD, BOOTSTRAP_95, REPEATS_STD, REPEATS_95, SCATTER_STD, ANGLES_STD,
    ANGLES_RANGE, STANDARD_U, EXPANDED_U,
)  # fmt: skip


def kind_of(description: str) -> IntervalSource:
    """The kind of an identify fit's intervals from how they were found (``IntervalSummary.description``
    or the estimator's ``cov_type``): bootstrap, repeats, else the fit's own."""
    if "bootstrap" in description:
        return IntervalSource.BOOTSTRAP
    if "repeat" in description:
        return IntervalSource.REPEATS
    return IntervalSource.FIT


def legend(columns: dict[str, IntervalLabel]) -> dict[str, str]:
    """``--json``'s ``intervals``: each interval column or key and its label."""
    return {column: label.text for column, label in columns.items()}
