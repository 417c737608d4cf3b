"""The AUV workflows as data: an identification against the standard derivatives, and the three-model
validation (seed 003). ``tankdaq auv identify`` and ``auv validate`` print what these return."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from .identify import SeparateIdentifier, default_window_s, relative_errors
from .model import StateRecord
from .sensitivity import SensitivityResult
from .validate import ValidationResult, resimulate
from .vehicle import TERM_BY_NAME, Vehicle

#: Derivatives ranked by sensitivity needed before their ranking is compared with the errors.
MIN_RANKED = 4


def sensitivity_vs_error(
    sensitivity: SensitivityResult, errors: Mapping[str, float]
) -> dict[str, float] | None:
    """Does a more sensitive derivative come out better identified? Spearman's rho between the
    sensitivity index and the relative error, and the mean error of each half of the ranking (None
    with fewer than ``MIN_RANKED`` derivatives both ranked and identified)."""
    ranked = [n for n in sensitivity.ranking if n in errors]
    if len(ranked) < MIN_RANKED:
        return None
    from scipy.stats import spearmanr  # scipy.stats is slow to import: only here

    half = len(ranked) // 2
    rho, p_value = spearmanr([sensitivity.index[n] for n in ranked], [errors[n] for n in ranked])
    return {
        "spearman_rho": float(rho),
        "p_value": float(p_value),
        "mean_error_top_half": float(np.mean([errors[n] for n in ranked[:half]])),
        "mean_error_bottom_half": float(np.mean([errors[n] for n in ranked[half:]])),
    }


def identification_report(
    ident: SeparateIdentifier, vehicle: Vehicle, sensitivity: SensitivityResult | None, gamma_source: str
) -> dict[str, object]:
    """The identified derivatives against the vehicle's standard ones (the ``auv identify --json``
    object): per derivative its error and sensitivity, per equation its bias, gamma and R^2."""
    errors = relative_errors(ident.derivatives_, vehicle.derivatives)
    rows = [
        {
            "derivative": name,
            "multiplies": TERM_BY_NAME[name].multiplies,
            "standard": vehicle.coefficient(name),
            "identified": value,
            "std_error": ident.std_[name],
            "relative_error": errors.get(name),
            "sensitivity_index": sensitivity.index.get(name) if sensitivity else None,
            "dominant": (name in sensitivity.dominant) if sensitivity else None,
        }
        for name, value in ident.derivatives_.items()
    ]
    report: dict[str, object] = {
        "vehicle": vehicle.name,
        "method": ident.method,
        "window_s": ident.window_s if ident.window_s is not None else default_window_s(vehicle),
        "derivatives": rows,
        "bias": ident.bias_,
        "bias_std": ident.bias_std_,
        "gamma": {eq: fit.gamma for eq, fit in ident.equations_.items()},
        "gamma_chosen_on": gamma_source if ident.method == "lssvm" else None,
        "r2_equation": {eq: fit.r2 for eq, fit in ident.equations_.items()},
    }
    compared = sensitivity_vs_error(sensitivity, errors) if sensitivity else None
    if compared is not None:
        report["sensitivity_vs_error"] = compared
    return report


@dataclass
class ModelValidation:
    """Three identified models re-simulating a record: the ones that could, and why the others not."""

    dominant: list[str]
    results: list[ValidationResult]
    failures: dict[str, str] = field(default_factory=dict)


def validate_models(
    train: StateRecord,
    target: StateRecord,
    vehicle: Vehicle,
    sensitivity: SensitivityResult,
    method: str = "lssvm",
    mode: str | None = None,
    target_name: str = "the record",
) -> ModelValidation:
    """Identify from ``train`` all derivatives, then only the dominant ones (the others kept at their
    standard values, or dropped), and re-simulate ``target`` with each. A model that cannot re-simulate
    (a reduced model whose pitch never reaches the switching angle) is a failure with its reason; none
    that can is an ``InputError``."""
    dominant = list(sensitivity.dominant)
    others = {n: vehicle.coefficient(n) for n in vehicle.present_terms() if n not in dominant}
    settings: dict[str, dict[str, Any]] = {
        "identified, all derivatives": {},
        "identified dominant, others standard": {"terms": dominant, "fixed": others},
        "identified dominant, others dropped": {"terms": dominant},
    }
    validation = ModelValidation(dominant, [])
    for label, extra in settings.items():
        model = SeparateIdentifier(vehicle, method=method, **extra).fit(train).model()
        try:
            validation.results.append(resimulate(target, model, label, mode))
        except InputError as exc:
            validation.failures[label] = str(exc)
    if not validation.results:
        reason = next(iter(validation.failures.values()))
        raise InputError(f"no model could re-simulate {target_name}: {reason}")
    return validation
