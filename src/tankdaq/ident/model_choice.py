"""The default model, chosen by the data: the best of a small family on held-out data, physics first.

A fixed default (b1,b2,c1,c3) fits a SWATH decay whose damping is cubic with b1 < 0: linear and
quadratic damping trade off over the narrow amplitude band of one decay (reference §5). Here
every model of ``physics.models.MODEL_FAMILY`` is fitted twice by output error: on the whole
decays (its values, checked by ``ident.plausibility``) and on the first ``FIT_FRACTION`` of every
run, which then predicts the rest (its held-out angle RMS, deg: the split-sample check
``diagnose`` uses, so a model that only bends the first cycles to its extra terms loses). The
chosen model is the simplest plausible one within ``PARSIMONY`` of the best plausible held-out
RMS; when none is plausible, the best by held-out RMS, and its findings stay on the result as
warnings.

``model_for`` is the one place every command asks which model to fit (``identify``, each ``campaign``
group, ``demo``, the guided session's report, the measured side of ``diagnose --simulation``): the
same decays get the same model whatever the command. The choice reads the decays alone, never a hull
file (a hull's checks warn on the chosen fit), so a campaign that finds the hull by name and an
``identify`` without ``--hull`` agree.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import IdentificationError
from ..physics.models import AUTO, MODEL_FAMILY, is_auto, model_name, resolve_model
from ..records import DecayRun
from .output_error import OutputErrorFit
from .plausibility import Implausibility, check_runs

#: Fraction of every run (in time) the split-sample fit sees; the rest is predicted.
FIT_FRACTION = 0.6
#: A larger model must predict the held-out part this much better (relative RMS) to be chosen.
PARSIMONY = 0.05


@dataclass
class Candidate:
    """One model of the family: its held-out score and whether its whole-data fit is plausible."""

    terms: tuple[str, ...]
    held_out_rms_deg: float = math.nan
    findings: list[Implausibility] = field(default_factory=list)
    error: str = ""

    @property
    def plausible(self) -> bool:
        return not self.error and not any(not f.about_data for f in self.findings)

    def as_dict(self) -> dict[str, Any]:
        return {
            "model": ",".join(self.terms),
            "name": model_name(self.terms),
            "held_out_rms_deg": self.held_out_rms_deg if math.isfinite(self.held_out_rms_deg) else None,
            "plausible": self.plausible,
            "warnings": [f.message for f in self.findings] + ([self.error] if self.error else []),
        }


@dataclass
class ModelChoice:
    """The chosen terms, the one line that says why, and every candidate's score."""

    terms: tuple[str, ...]
    reason: str
    candidates: list[Candidate]

    @property
    def by_data(self) -> bool:
        """True when the data chose the model (candidates were scored), False for a model asked for."""
        return bool(self.candidates)

    def as_dict(self) -> dict[str, Any]:
        if not self.candidates:  # a model asked for: nothing was scored
            return {"chosen": ",".join(self.terms), "reason": self.reason}
        return {
            "chosen": ",".join(self.terms),
            "reason": self.reason,
            "held_out": f"angle RMS (deg) on the last {1 - FIT_FRACTION:.0%} of every run, fitted on "
            "the rest",
            "scores": [c.as_dict() for c in self.candidates],
        }


def split_runs(runs: Sequence[DecayRun], fraction: float = FIT_FRACTION) -> list[DecayRun]:
    """Each run's first ``fraction`` of its duration."""
    return [
        run.window(0, int(np.searchsorted(run.t, run.t[0] + fraction * (run.t[-1] - run.t[0]))))
        for run in runs
    ]


def score(terms: tuple[str, ...], runs: Sequence[DecayRun]) -> Candidate:
    """Fit ``terms`` on the whole runs (plausibility) and on their first part (held-out RMS, deg)."""
    candidate = Candidate(terms)
    try:
        whole = OutputErrorFit(terms, compute_diagnostics=False).fit(list(runs))
        candidate.findings = check_runs(whole.coefficients_, runs, whole.offsets_)
        first = split_runs(runs)
        early = OutputErrorFit(terms, compute_diagnostics=False).fit(first, start=whole)
    except IdentificationError as exc:
        candidate.error = f"not fitted: {exc}"
        return candidate
    squares, count = 0.0, 0
    for r, (run, part) in enumerate(zip(runs, first, strict=True)):
        predicted, _ = early.predict(run, run_index=r)
        held = np.arange(run.t.size) >= part.t.size
        held &= run.kept  # clipped samples are no test of a model either
        squares += float(np.sum((run.angle[held] - predicted[held]) ** 2))
        count += int(np.count_nonzero(held))
    candidate.held_out_rms_deg = math.degrees(math.sqrt(squares / count)) if count else math.nan
    return candidate


def choose_model(runs: Sequence[DecayRun], family: Sequence[str] = MODEL_FAMILY) -> ModelChoice:
    """The family scored on ``runs``; see the module docstring for the rule."""
    candidates = [score(resolve_model(m), runs) for m in family]
    scored = [c for c in candidates if math.isfinite(c.held_out_rms_deg)]
    if not scored:
        raise IdentificationError(
            "no model of the family could be fitted: " + "; ".join(c.error for c in candidates if c.error)
        )
    plausible = [c for c in scored if c.plausible]
    if plausible:
        best = min(c.held_out_rms_deg for c in plausible)
        chosen = next(c for c in plausible if c.held_out_rms_deg <= best * (1 + PARSIMONY))
        dropped = [model_name(c.terms) for c in scored if not c.plausible]
        reason = (
            f"model {model_name(chosen.terms)} chosen by data: held-out RMS "
            f"{chosen.held_out_rms_deg:.3g} deg, the simplest plausible model within {PARSIMONY:.0%} "
            f"of the best ({best:.3g} deg)" + (f"; implausible: {', '.join(dropped)}" if dropped else "")
        )
    else:
        chosen = min(scored, key=lambda c: c.held_out_rms_deg)
        reason = (
            f"model {model_name(chosen.terms)} chosen by data (held-out RMS "
            f"{chosen.held_out_rms_deg:.3g} deg), but no model of the family is plausible: see the warnings"
        )
    return ModelChoice(chosen.terms, reason, candidates)


def model_for(runs: Sequence[DecayRun], model: str | Sequence[str] = AUTO) -> ModelChoice:
    """The model every command fits to ``runs``: chosen by the data (``choose_model``) for ``auto``,
    else ``model`` as asked (``--model``), its reason saying so."""
    if is_auto(model):
        return choose_model(runs)
    terms = resolve_model(model)
    return ModelChoice(terms, f"model {model_name(terms)} given by --model", [])
