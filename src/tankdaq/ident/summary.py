"""A fit's summary as the rooms pass it (identify, the report, the catalogue): typed, frozen.

``FitSummary.to_dict`` is the JSON object ``tankdaq identify --json`` prints and the files keep, its keys
in the order they have always had; the fields that only ``tankdaq.identify`` adds (the condition, the
model choice, the budget, full scale) are absent from it until set.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .model_choice import ModelChoice


@dataclass(frozen=True)
class ModelTerms:
    """The model fitted: its name (``physics.models.model_name``) and its terms in order."""

    name: str
    terms: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "terms": list(self.terms)}


@dataclass(frozen=True)
class Coefficient:
    """One fitted term per unit total inertia (SI, rad): value, standard deviation, 95 % interval."""

    value: float
    std: float
    ci95: tuple[float, float]
    unit: str

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "std": self.std, "ci95": list(self.ci95), "unit": self.unit}


@dataclass(frozen=True)
class DampingRow:
    """B_eq/I at one tested amplitude, and B̂44 where the hull gives inertia and beam (roll)."""

    amplitude_deg: float
    value_per_s: float
    std: float
    b44_hat: float | None = None

    def to_dict(self) -> dict[str, Any]:
        row = {"amplitude_deg": self.amplitude_deg, "value_per_s": self.value_per_s, "std": self.std}
        return row if self.b44_hat is None else row | {"b44_hat": self.b44_hat}


@dataclass(frozen=True)
class BertinRow:
    """Bertin's N at one tested amplitude."""

    amplitude_deg: float
    value_per_deg: float
    std: float

    def to_dict(self) -> dict[str, Any]:
        return {"amplitude_deg": self.amplitude_deg, "value_per_deg": self.value_per_deg, "std": self.std}


@dataclass(frozen=True)
class FitSummary:
    """What ``ident.report.summarize`` found (angles in deg at this edge); ``runs``, ``extinction``,
    ``plausibility``, ``dimensional`` and the identify-only parts are the JSON-ready rows their own rooms
    give. ``condition`` is written whenever ``condition_label`` is (None for a pooled fit)."""

    model: ModelTerms
    method: str
    axis: str
    coefficients: Mapping[str, Coefficient]
    intervals: str
    interval_labels: Mapping[str, str]
    offset_deg: tuple[float, ...]
    natural_period_s: float
    damping_ratio: float
    seed_objective: float
    r2_angle: float
    nrmse: float
    bic: float | None
    runs: tuple[Mapping[str, Any], ...]
    b_eq: tuple[DampingRow, ...]
    bertin_n: tuple[BertinRow, ...]
    extinction: Mapping[str, list[float]]
    plausibility: tuple[Mapping[str, Any], ...]
    warnings: tuple[str, ...]
    elapsed_s: float
    dimensional: Mapping[str, Any] | None = None
    condition_label: str | None = None
    model_choice: ModelChoice | None = None
    budget: tuple[Mapping[str, Any], ...] | None = None
    condition: Mapping[str, Any] | None = None
    conditions: str | None = None
    full_scale: Mapping[str, Any] | None = None

    @property
    def values(self) -> dict[str, float]:
        """Each term's fitted value."""
        return {term: c.value for term, c in self.coefficients.items()}

    @property
    def total_inertia_kg_m2(self) -> float | None:
        """The total inertia the hull gives (None without a hull, or one lacking displacement or GM)."""
        found = (self.dimensional or {}).get("total_inertia_kg_m2")
        return None if found is None else float(found)

    def to_dict(self) -> dict[str, Any]:
        """The JSON object, keys in their printed order."""
        found: dict[str, Any] = {
            "model": self.model.to_dict(),
            "method": self.method,
            "axis": self.axis,
            "coefficients": {term: c.to_dict() for term, c in self.coefficients.items()},
            "intervals": self.intervals,
            "interval_labels": dict(self.interval_labels),
            "offset_deg": list(self.offset_deg),
            "natural_period_s": self.natural_period_s,
            "damping_ratio": self.damping_ratio,
            "seed_objective": self.seed_objective,
            "r2_angle": self.r2_angle,
            "nrmse": self.nrmse,
            "bic": self.bic,
            "runs": [dict(run) for run in self.runs],
            "b_eq": [row.to_dict() for row in self.b_eq],
            "bertin_n": [row.to_dict() for row in self.bertin_n],
            "extinction": {key: list(values) for key, values in self.extinction.items()},
            "plausibility": [dict(finding) for finding in self.plausibility],
            "warnings": list(self.warnings),
            "elapsed_s": self.elapsed_s,
        }
        optional = {
            "dimensional": _plain(self.dimensional),
            "condition_label": self.condition_label,
            "model_choice": None if self.model_choice is None else self.model_choice.as_dict(),
            "budget": None if self.budget is None else [dict(b) for b in self.budget],
        }
        found |= {key: value for key, value in optional.items() if value is not None}
        if self.condition_label is not None:
            found["condition"] = _plain(self.condition)
        if self.conditions is not None:
            found["conditions"] = self.conditions
        if self.full_scale is not None:
            found["full_scale"] = dict(self.full_scale)
        return found


def _plain(value: Mapping[str, Any] | None) -> dict[str, Any] | None:
    return None if value is None else dict(value)
