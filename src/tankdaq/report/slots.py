"""The report's places for what other parts of tankdaq compute as DataFrames: a quantity's
uncertainty budget and the IMO table of Bertin's N against mean amplitude. Each is a ``ReportTable`` the
renderers show as any other (title, caption, interval labels), added to a condition's section by
``report.make`` (``condition_section(extra=...)``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

from ..ident.interval_labels import EXPANDED_U, IntervalLabel
from .content import ReportTable

if TYPE_CHECKING:
    import pandas as pd


def budget_table(
    key: str, quantity: str, frame: pd.DataFrame, intervals: Mapping[str, IntervalLabel] | None = None
) -> ReportTable:
    """A quantity's uncertainty budget (columns source, value, sensitivity, contribution, share):
    the sources' contributions combined, and expanded with k = 2."""
    caption = (
        f"Uncertainty budget of {quantity} (ISO-GUM, ITTC 7.5-02-01-01): each source's value, its "
        f"sensitivity and its contribution to the combined standard uncertainty; {EXPANDED_U.text}: "
        "expanded with k = 2."
    )
    return ReportTable.from_frame(key, f"Uncertainty budget: {quantity}", frame, caption, intervals)


def imo_table(
    key: str, frame: pd.DataFrame, intervals: Mapping[str, IntervalLabel] | None = None, note: str = ""
) -> ReportTable:
    """Bertin's N against mean amplitude at 10, 15, 20 and 25 deg where the decays cover them; ``note``
    says which amplitudes they do not reach."""
    caption = (
        "Bertin's N against mean amplitude (MSC.1/Circ.1200), interpolated where the decays cover the "
        "amplitude; an amplitude not reached says so."
    ) + (f" {note}" if note else "")
    return ReportTable.from_frame(key, "IMO table: Bertin's N", frame, caption, intervals)
