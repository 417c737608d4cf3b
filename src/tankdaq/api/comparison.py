"""``tankdaq.compare_models``: every seed formula and ITTC form fitted to the same decays, side by side;
``tankdaq identify --compare`` is this call.

Each model (``physics.models.COMPARE_MODELS``, one fit per distinct term set) is fitted with the same
method and scored by the seeds' objective, R² of the angle, BIC and, with several decays, the
leave-one-decay-out error (``ident.comparison``): a table to choose a model by, not a result to report.
"""

from __future__ import annotations

import html
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from . import arguments
from .identification import Reading, Source, load_runs, to_json, truncations
from .progress import Kept, Progress
from .recording import sources_given

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True, eq=False)  # holds a DataFrame: compared by identity
class ModelComparison:
    """What ``compare_models`` found. ``rows`` one per term set, best (lowest BIC) first: ``models`` (the
    names that share it), ``terms``, ``n_terms``, ``seed_objective``, ``r2_angle``, ``bic``,
    ``held_out_rms_deg`` (None for a single decay); ``document`` the
    object ``tankdaq identify --compare --json`` prints; ``warnings`` (decays of several conditions
    compared together), ``cuts`` (where each free decay was cut), ``notices`` the reading's lines,
    ``truncated_files`` the recordings cut short.

    >>> found = tankdaq.compare_models(["run01.mcap", "run02.mcap"])  # doctest: +SKIP
    >>> found.table[["models", "bic", "held_out_rms_deg"]]  # doctest: +SKIP
    """

    rows: list[dict[str, Any]]
    warnings: list[str]
    cuts: list[str]
    notices: list[str]
    truncated_files: list[str]

    @property
    def table(self) -> pd.DataFrame:
        import pandas as pd

        table = pd.DataFrame(self.rows)
        table.attrs["warnings"] = self.warnings
        return table

    @property
    def document(self) -> dict[str, Any]:
        cut = self.truncated_files
        return {
            "compare": self.rows,
            "cuts": self.cuts,
            "warnings": self.warnings,
            "truncated": bool(cut),
            "truncated_files": cut,
        }

    def to_json(self) -> str:
        """The text ``tankdaq identify --compare --json`` prints (NaN and infinities as null)."""
        return to_json(self.document)

    def text(self) -> str:
        """The table ``tankdaq identify --compare`` prints."""
        from ..ident.comparison import compare_text

        return compare_text(self.rows)

    def _repr_html_(self) -> str:
        warnings = "".join(f"<li>warning: {html.escape(line)}</li>" for line in self.warnings)
        return (f"<ul>{warnings}</ul>" if warnings else "") + self.table.to_html(index=False)


def compare_models(
    sources: Source | Sequence[Source],
    *,
    method: str = "oe",
    reading: Reading | None = None,
    progress: Progress | None = None,
) -> ModelComparison:
    """Fit every seed formula and ITTC form (``physics.models.COMPARE_MODELS``) to the decays with
    ``method`` (``oe``, ``ee``, ``ga``, ``pso``) and score them side by side; ``reading`` as
    ``identify``'s. Decays of several conditions are compared together, with a warning.

    >>> tankdaq.compare_models("run.mcap").text()  # doctest: +SKIP
    """
    from ..ident.comparison import compare_models as fit_models
    from ..ident.comparison import group_models
    from ..ident.conditions import group_conditions, grouping_line
    from ..ident.estimators import make_estimator
    from ..ident.free_decay import cut_lines
    from ..live.preparation import prepare_identifier
    from ..physics.models import COMPARE_MODELS, MODEL_FAMILY

    sources = sources_given(sources)
    method = arguments.text(method, "method", "an estimator's name: oe, ee, ga or pso")
    reading = arguments.optional_instance(reading, "reading", Reading, "a tankdaq.Reading or None")
    kept = Kept(arguments.progress(progress))
    make_estimator(method, MODEL_FAMILY[0])  # an unknown method fails before any reading
    runs = load_runs(sources, reading or Reading(), kept)
    cut = truncations(runs)
    for line in cut.values():
        kept.line(line)
    groups = group_conditions(runs)
    pooled = [grouping_line(groups, joint=True)] if len(groups) > 1 else []
    prepare_identifier(MODEL_FAMILY[-1], kept.line)  # the native kernels: built once, on the first run
    with kept.task("fitting models", len(group_models(COMPARE_MODELS))) as advance:
        count = itertools.count(1)
        rows = fit_models(runs, COMPARE_MODELS, method, lambda name: advance(next(count), description=name))
    return ModelComparison(rows, pooled, cut_lines(runs), kept.lines, list(cut))
