"""The estimators by method name, so the CLI dispatches through a table others can extend.

``oe`` (output error, the default) and ``ee`` (equation error) live here; the
seeds' GA/PSO searches register themselves with ``register_estimator``. A
factory takes the model terms and keyword settings and returns an unfitted
estimator with ``fit(runs) -> self`` and at least ``terms_``,
``coefficients_``, ``std_``, ``ci95_``, ``offsets_`` and ``initial_states_``.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from typing import Any

from ..errors import InputError
from .equation_error import EquationErrorFit
from .evolutionary import SEED_ESTIMATORS
from .output_error import OutputErrorFit

EstimatorFactory = Callable[..., Any]

ESTIMATORS: dict[str, EstimatorFactory] = {"oe": OutputErrorFit, "ee": EquationErrorFit}
ESTIMATORS.update(SEED_ESTIMATORS)  # the seeds' GA/PSO: ga, pso, ga-seed000 ... (ident.evolutionary)


def register_estimator(name: str, factory: EstimatorFactory) -> None:
    """Make ``--method NAME`` (and ``make_estimator``) build ``factory(terms, **settings)``."""
    ESTIMATORS[name] = factory


def make_estimator(method: str, terms: str | Sequence[str], **settings: Any) -> Any:
    """An unfitted estimator for a method name; unknown names list the known ones."""
    if method not in ESTIMATORS:
        raise InputError(f"unknown method {method!r}; known: {', '.join(ESTIMATORS)}")
    return ESTIMATORS[method](terms, **settings)


def reports_progress(method: str) -> bool:
    """Whether ``method``'s estimator takes a ``progress`` setting, called with (done, total) as it goes
    (the seeds' GA/PSO: their generations), so a caller can hand it one in the constructor."""
    return "progress" in inspect.signature(ESTIMATORS[method]).parameters


__all__ = [
    "ESTIMATORS",
    "EquationErrorFit",
    "OutputErrorFit",
    "make_estimator",
    "register_estimator",
    "reports_progress",
]
