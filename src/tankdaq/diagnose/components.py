"""A prediction's own components as corrections: which of them to scale, by what factor, in B44.

A comparison corrects a simulation term by term (its b1, b2, c1 ... freed and refitted to the
measurement). For a prediction made of components (simplified Ikeda: friction, wave and lift carry the
equivalent model's b1, eddy and bilge keel its b2) a changed term is a scaling of those components: the
factor if the whole part is scaled, the factor if one component alone carries the change (a decay cannot
tell components of one form apart: lift and wave are both linear), and the change of B_eq in N·m·s at
the largest tested amplitude, at model and full scale. For a time series or a model the components are
its fitted terms. A term that ends below the simulation's is an excess and is named so: "the
prediction's quadratic damping (eddy) is 2.5x the measured", not a missing effect with a minus sign.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from ..physics.ikeda import COMPONENTS, QUADRATIC_EQUIVALENT, IkedaPrediction, fit_parts
from ..physics.terms import TERM_TABLE
from .correction import Correction

#: The terms a component scaling is stated for (restoring terms are a stiffness, not a component).
DAMPING_TERMS = ("b1", "b2", "b3")


def prediction_shares(
    prediction: IkedaPrediction, amplitudes_rad: Sequence[float]
) -> dict[str, tuple[str, float]]:
    """Each non-zero Ikeda component's part of the equivalent model over the amplitudes: key -> ("b1", its
    part of b1) for friction, wave and lift, ("b2", its part of b2) for eddy and bilge keel."""
    amplitudes = sorted({float(a) for a in amplitudes_rad})
    parts = [
        {k: prediction.per_inertia(v) for k, v in prediction.components(a).items() if k in COMPONENTS}
        for a in amplitudes
    ]
    return table_shares(prediction.omega_rad_s, amplitudes, parts)


def table_shares(
    omega_rad_s: float, amplitudes_rad: Sequence[float], parts: Sequence[Mapping[str, float]]
) -> dict[str, tuple[str, float]]:
    """``prediction_shares`` from components per unit inertia at each amplitude (``fit_parts``)."""
    shares = {}
    for key, (_, _, form) in COMPONENTS.items():
        if not any(row.get(key, 0.0) for row in parts):
            continue
        index = 0 if form == "linear" else 1
        value = fit_parts(
            omega_rad_s, amplitudes_rad, [{k: row.get(k, 0.0) for k in COMPONENTS} for row in parts], [key]
        )[index]
        if value > 0:
            shares[key] = ("b1" if index == 0 else "b2", value)
    return shares


@dataclass
class ComponentScaling:
    """One term of the simulation changed by the correction, as a scaling of the components it holds."""

    term: str
    predicted: float  # the simulation's value (per unit inertia)
    final: float  # the corrected model's
    members: dict[str, float]  # component name -> its part of the predicted term
    prediction: bool  # components of a prediction (else the simulation's own fitted terms)
    #: B_eq per unit inertia (1/s) per unit of the term at ``amplitude_deg`` (1 for b1), and the corrected
    #: model's B_eq of the same form there: a cubic damping added beside the quadratic is the same
    #: amplitude-dependent part (over one decay the two trade off), so the part is compared in B_eq.
    per_term: float = 1.0
    final_part: float | None = None
    amplitude_deg: float = math.nan
    b44_model_n_m_s: float | None = None  # change of B_eq * I at amplitude_deg, model scale
    b44_full_n_m_s: float | None = None  # the same at full scale (Froude)
    notes: list[str] = field(default_factory=list)

    @property
    def _final(self) -> float:
        """The corrected part in units of the term (B_eq at the amplitude / ``per_term``)."""
        return self.final if self.final_part is None else self.final_part / self.per_term

    @property
    def excess(self) -> bool:
        return self._final < self.predicted

    @property
    def verdict_word(self) -> str:
        return "excess" if self.excess else "too little"

    @property
    def times_measured(self) -> float:
        """How many times the measured the simulation has of this part (inf when the measured has none)."""
        return self.predicted / self._final if self._final > 0 else math.inf

    @property
    def factor(self) -> float:
        """Every component of the part scaled alike."""
        return max(self._final, 0.0) / self.predicted if self.predicted else math.inf

    def alone(self) -> dict[str, float]:
        """The factor of each component if it alone carried the change (below zero: it cannot)."""
        change = max(self._final, 0.0) - self.predicted
        return {name: 1.0 + change / share for name, share in self.members.items() if share > 0}

    @property
    def label(self) -> str:
        """``the prediction's quadratic damping (eddy, bilge keel)``."""
        what = "prediction's" if self.prediction else "simulation's"
        description = TERM_TABLE[self.term].description if self.term in TERM_TABLE else self.term
        return f"the {what} {description} ({', '.join(self.members)})"

    @property
    def line(self) -> str:
        unit = TERM_TABLE[self.term].unit if self.term in TERM_TABLE else ""
        times = "more than" if math.isinf(self.times_measured) else f"{self.times_measured:.3g}x"
        head = self.verdict_word
        alone = ", ".join(
            f"{name} alone x{f:.3g}" if f >= 0 else f"{name} alone cannot (below zero)"
            for name, f in self.alone().items()
        )
        text = (
            f"{head}: {self.label} is {times} the measured: scaled x{self.factor:.3g} "
            f"({self.term} {self.predicted:.4g} -> {self.final:.4g} {unit}"
        )
        if self.final_part is not None and abs(self._final - self.final) > 1e-12:
            text += (
                f"; with the added terms of its form {self._final:.4g} {unit} at {self.amplitude_deg:.3g} deg"
            )
        text += ")"
        if len(self.members) > 1 or self.prediction:
            text += f"; or {alone}"
        if self.b44_model_n_m_s is not None:
            text += f"; B_eq at {self.amplitude_deg:.3g} deg {self.b44_model_n_m_s:+.4g} N m s at model scale"
            if self.b44_full_n_m_s is not None:
                text += f", {self.b44_full_n_m_s:+.4g} N m s at full scale"
        return text + "".join(f" ({note})" for note in self.notes)


def component_scalings(
    shares: Mapping[str, tuple[str, float]] | None,
    simulated: Mapping[str, float],
    corrected: Mapping[str, float],
    changed: Sequence[str],
    omega_rad_s: float,
    amplitude_rad: float,
    fix: Correction,
) -> list[ComponentScaling]:
    """Every changed term the simulation holds, as a scaling of its components (``shares``: a prediction's;
    None: the simulation's own terms), with B_eq's change in N·m·s at ``amplitude_rad``."""
    out = []
    for term in dict.fromkeys(changed):
        if not simulated.get(term):
            continue
        if shares:
            members = {COMPONENTS[k][1]: v for k, (t, v) in shares.items() if t == term}
        else:
            members = {term: simulated[term]}
        if not members:
            continue
        scaling = ComponentScaling(term, simulated[term], corrected[term], members, bool(shares))
        if term in DAMPING_TERMS:
            speed = omega_rad_s * amplitude_rad
            per_term = {"b1": 1.0, "b2": QUADRATIC_EQUIVALENT * speed, "b3": 0.75 * speed**2}
            form = [term] if term == "b1" else [t for t in ("b2", "b3") if t == term or t not in simulated]
            scaling.per_term = per_term[term]
            scaling.final_part = sum(per_term[t] * corrected.get(t, 0.0) for t in form)
            scaling.amplitude_deg = math.degrees(amplitude_rad)
        if scaling.final_part is not None and fix.total_inertia_kg_m2 is not None:
            change = scaling.final_part - scaling.per_term * scaling.predicted
            scaling.b44_model_n_m_s = change * fix.total_inertia_kg_m2
            if fix.scale_factor is not None:
                scaling.b44_full_n_m_s = scaling.b44_model_n_m_s * fix.scale_factor**4.5
                if "friction" in members:
                    scaling.notes.append("friction does not follow Froude: correct it by Reynolds number")
        out.append(scaling)
    return out
