"""An uncertainty budget for every reported quantity, in the ISO-GUM form ITTC uses (7.5-02-01-01;
7.5-02-07-02.1 Appendix A; reference lab-practice §6).

Each quantity (``budget_inputs.reported_quantities``) gets one row per source: its kind (A or B), its
standard uncertainty with unit, the sensitivity coefficient (a central difference of the measurement
model) and the contribution |c| u; the combined standard uncertainty is their root sum of squares, and
the expanded uncertainty U = k u_c with k = 2 (about 95 %). Sources:

- Type A, the scatter of the decays: from repeats (the standard deviation of the mean of the quantity
  over decays fitted one by one, n said) or, with one decay, the fit's own covariance (HAC: correlated
  coefficients through the covariance, not term by term). The two estimate the same scatter, so one is
  counted, never both: with repeats, the larger of the two (three repeats give a standard deviation of
  two degrees of freedom, which alone would cover the truth in about 82 % at k = 2);
- Type B, the device (angle accuracy and resolution, clock, SampleTimeFine) and the hull file's GM,
  displacement and gyradius uncertainties (``budget_inputs``).

``monte_carlo`` propagates the same sources by GUM Supplement 1 (JCGM 101) as a check on the linear
propagation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .budget_inputs import EvaluationType, Quantity, Source, true_coefficients

#: The coverage factor and what it covers.
COVERAGE_FACTOR = 2.0
#: How the budget's values are labelled (the convention of docs/intervals.md).
EXPANDED_LABEL = "U (k=2, ≈95 %, expanded)"
STANDARD_LABEL = "u (1σ, standard)"
#: Relative step of the sensitivity coefficients' central differences.
STEP = 1e-6
#: A contribution below this fraction of the value is the central difference's rounding, not a
#: dependence (Bertin's N on the clock, analytically none): its source is not an input of the quantity.
NEGLIGIBLE = 1e-9


@dataclass(frozen=True)
class BudgetRow:
    """One source of one quantity: u in the source's unit, the sensitivity in the quantity's unit per
    source unit, the contribution |c| u in the quantity's unit, and its share of u_c^2."""

    source: str
    kind: EvaluationType
    u: float
    unit: str
    sensitivity: float
    contribution: float
    share: float
    note: str = ""


@dataclass(frozen=True)
class Budget:
    """The budget of one reported quantity: its value, rows, combined u_c and expanded U = k u_c."""

    quantity: str
    key: str
    unit: str
    value: float
    rows: tuple[BudgetRow, ...]
    combined: float
    coverage_factor: float
    expanded: float
    notes: tuple[str, ...] = ()

    @property
    def coverage(self) -> str:
        return f"k={self.coverage_factor:g}, ≈95 %"

    def as_dict(self) -> dict[str, Any]:
        """The budget as ``--json`` and the catalogue hold it (kinds as "A"/"B")."""
        return {
            "quantity": self.quantity,
            "key": self.key,
            "unit": self.unit,
            "value": self.value,
            "combined_u": self.combined,
            "coverage_factor": self.coverage_factor,
            "expanded_u": self.expanded,
            "coverage": self.coverage,
            "labels": {"combined_u": STANDARD_LABEL, "expanded_u": EXPANDED_LABEL},
            "rows": [
                {
                    "source": r.source,
                    "kind": r.kind.value,
                    "u": r.u,
                    "unit": r.unit,
                    "sensitivity": r.sensitivity,
                    "contribution": r.contribution,
                    "share": r.share,
                    "note": r.note,
                }
                for r in self.rows
            ],
            "notes": list(self.notes),
        }


def from_rows(
    quantity: Quantity, value: float, rows: Sequence[BudgetRow], notes: Sequence[str] = ()
) -> Budget:
    """A budget of ``rows``: u_c their root sum of squares, shares of u_c^2, U = 2 u_c."""
    combined = math.sqrt(math.fsum(r.contribution**2 for r in rows))
    shared = tuple(
        replace(r, share=r.contribution**2 / combined**2 if combined > 0 else math.nan) for r in rows
    )
    return Budget(
        quantity.name,
        quantity.key,
        quantity.unit,
        value,
        shared,
        combined,
        COVERAGE_FACTOR,
        COVERAGE_FACTOR * combined,
        tuple(notes),
    )


def without(budget: Budget, source: str) -> Budget:
    """The budget with the row of ``source`` removed and u_c, U and the shares made again."""
    rows = [r for r in budget.rows if r.source != source]
    quantity = Quantity(budget.quantity, budget.unit, budget.key, lambda c, x: budget.value)
    return from_rows(quantity, budget.value, rows, budget.notes)


def evaluate(quantity: Quantity, coefficients: Mapping[str, float], inputs: Mapping[str, float]) -> float:
    """The quantity from the measured coefficients with the inputs at ``inputs``."""
    return float(quantity.fn(true_coefficients(coefficients, inputs), inputs))


def sensitivity(
    quantity: Quantity, coefficients: Mapping[str, float], inputs: Mapping[str, float], source: Source
) -> float:
    """d quantity / d source (per the source's unit), by a central difference of the measurement model."""
    x0 = inputs[source.input]
    step = STEP * max(abs(x0), 1e-9)
    up, down = dict(inputs), dict(inputs)
    up[source.input], down[source.input] = x0 + step, x0 - step
    slope = (evaluate(quantity, coefficients, up) - evaluate(quantity, coefficients, down)) / (2 * step)
    return slope * source.per_unit


def fit_u(
    quantity: Quantity, coefficients: Mapping[str, float], inputs: Mapping[str, float], covariance: np.ndarray
) -> float:
    """The quantity's standard uncertainty from the coefficient covariance (gradient' cov gradient)."""
    names = list(coefficients)
    gradient = np.zeros(len(names))
    for i, name in enumerate(names):
        step = STEP * max(abs(coefficients[name]), 1e-3)
        up, down = dict(coefficients), dict(coefficients)
        up[name] += step
        down[name] -= step
        gradient[i] = (evaluate(quantity, up, inputs) - evaluate(quantity, down, inputs)) / (2 * step)
    return math.sqrt(max(float(gradient @ covariance @ gradient), 0.0))


@dataclass(frozen=True)
class FitUncertainty:
    """The fit's coefficients and covariance, and (with repeats) each decay's own coefficients."""

    coefficients: dict[str, float]
    covariance: np.ndarray
    cov_type: str
    per_decay: tuple[dict[str, float], ...] = ()
    decays: int = 1  # how many decays the fit holds (repeats not refitted one by one have no per_decay)


def type_a_row(quantity: Quantity, fit: FitUncertainty, inputs: Mapping[str, float]) -> tuple[BudgetRow, str]:
    """The Type A row (the decays' scatter) and the line that says how it was found."""
    from_fit = fit_u(quantity, fit.coefficients, inputs, fit.covariance)
    own = f"the fit ({fit.cov_type} covariance)"
    n = len(fit.per_decay)
    if n < 2:
        alone = fit.decays < 2
        note = "one decay" if alone else f"{fit.decays} decays fitted together"
        said = (
            "one decay: Type A is the fit's own interval; repeat the decay (3 or more) for repeats"
            if alone
            else f"Type A is the fit's own interval: its {fit.decays} decays were not fitted one by one"
        )
        return BudgetRow(own, EvaluationType.A, from_fit, quantity.unit, 1.0, from_fit, math.nan, note), said
    values = np.array([evaluate(quantity, c, inputs) for c in fit.per_decay])
    of_mean = float(np.std(values, ddof=1)) / math.sqrt(n)
    said = (
        f"Type A from {n} repeat decays: the larger of their std of the mean and the fit's own interval "
        "(both estimate the same scatter; counted once)"
    )
    if of_mean >= from_fit:
        name, u, note = f"repeats (std of the mean, n={n})", of_mean, f"the fit's own: {from_fit:.3g}"
    else:
        name, u, note = (
            f"{own[:-1]}; n={n} repeats)",
            from_fit,
            f"the repeats' std of the mean: {of_mean:.3g}",
        )
    return BudgetRow(name, EvaluationType.A, u, quantity.unit, 1.0, u, math.nan, note), said


def quantity_budget(
    quantity: Quantity, fit: FitUncertainty, inputs: Mapping[str, float], sources: Sequence[Source]
) -> Budget:
    """One quantity's budget: the Type A row, then one Type B row per source it depends on."""
    value = evaluate(quantity, fit.coefficients, inputs)
    type_a, said = type_a_row(quantity, fit, inputs)
    rows = [type_a]
    for source in sources:
        c = sensitivity(quantity, fit.coefficients, inputs, source)
        if math.isfinite(c) and abs(c) * source.u > NEGLIGIBLE * abs(value):  # a quantity's non-input: no row
            rows.append(
                BudgetRow(
                    source.name,
                    EvaluationType.B,
                    source.u,
                    source.unit,
                    c,
                    abs(c) * source.u,
                    math.nan,
                    source.note,
                )
            )
    return from_rows(quantity, value, rows, [said])


def budgets(
    quantities: Sequence[Quantity],
    fit: FitUncertainty,
    inputs: Mapping[str, float],
    sources: Sequence[Source],
) -> list[Budget]:
    """Every quantity's budget (those whose value is not finite, for want of an input, are left out)."""
    out = [quantity_budget(q, fit, inputs, sources) for q in quantities]
    return [b for b in out if math.isfinite(b.value) and math.isfinite(b.combined)]


def monte_carlo(
    quantity: Quantity,
    fit: FitUncertainty,
    inputs: Mapping[str, float],
    sources: Sequence[Source],
    draws: int = 20000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """GUM Supplement 1: the quantity's standard uncertainty and 95 % interval (std, low, high) from
    ``draws`` draws of every input (normal, at its u) and of the decays' scatter (the coefficients from
    the fit's covariance; with repeats, the Type A row's u added as a normal error)."""
    rng = np.random.default_rng(seed)
    names = list(fit.coefficients)
    centre = np.array([fit.coefficients[k] for k in names])
    type_a, _ = type_a_row(quantity, fit, inputs)
    repeats = len(fit.per_decay) >= 2 and type_a.source.startswith("repeats")
    drawn = (
        np.tile(centre, (draws, 1))
        if repeats
        else rng.multivariate_normal(centre, fit.covariance, size=draws, method="eigh")
    )
    values = np.empty(draws)
    for i in range(draws):
        x = dict(inputs)
        for source in sources:
            x[source.input] += rng.standard_normal() * source.u * source.per_unit
        values[i] = evaluate(quantity, dict(zip(names, drawn[i], strict=True)), x)
    if repeats:
        values += rng.standard_normal(draws) * type_a.u
    low, high = np.percentile(values, [2.5, 97.5])
    return float(np.std(values, ddof=1)), float(low), float(high)


def text_table(found: Sequence[Mapping[str, Any]]) -> list[str]:
    """Budgets (``Budget.as_dict``) as the text reports print them: per quantity, its rows, u_c and U."""
    lines = [
        f"  uncertainty budget (GUM; {STANDARD_LABEL}; {EXPANDED_LABEL})",
        "  per source: Type A/B, its u in its unit, c the sensitivity (quantity's unit per source's unit),",
        "  the contribution |c| u in the quantity's unit, its share of u_c^2; u_c = root sum of squares",
    ]
    for b in found:
        lines.append(
            f"  {b['quantity']}: {b['value']:.6g} {b['unit']}, u_c {b['combined_u']:.3g}, "
            f"U {b['expanded_u']:.3g} {b['unit']} ({b['coverage']})"
        )
        for r in b["rows"]:
            lines.append(
                f"    {r['kind']}  {r['source']:<44} u {r['u']:>9.3g} {r['unit']:<6} "
                f"c {r['sensitivity']:>10.3g}  contribution {r['contribution']:>9.3g}  "
                f"share {r['share']:>6.1%}"
            )
    notes = dict.fromkeys(note for b in found for note in b["notes"])
    return lines + [f"  budget: {note}" for note in notes]


def short_lines(label: str, found: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per quantity of one condition (a campaign's text): value, U and where Type A came from."""
    return [
        f"- {label}: {b['quantity']} {b['value']:.5g} ± {b['expanded_u']:.2g} {b['unit']} "
        f"(U, k=2; Type A: {b['rows'][0]['source']})"
        for b in found
        if b["key"] == "natural_period_s" or b["key"].startswith("b_eq_per_s@")
    ]
