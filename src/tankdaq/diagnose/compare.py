"""Simulation meets measurement: where a lab's simulation and its model test disagree, what it misses.

``SimulationComparison(simulation).fit(runs)`` identifies the simulation's own equation (a series by
ident's output-error engine; a model as given), re-simulates it from every measured release, compares
cycle by cycle (period, decrement curve, B_eq(phi_a) with 95 % intervals on both sides, the residual),
adds the missing effect (``diagnose.effects``, plus a linear damping or stiffness only off in value) by
fitting ONLY its term(s) with the simulation's own fixed, step by step while a step closes a real part
of the gap, and refits everything free beside it. The gap: RMS of the angle over the measured decay,
every model started from the same measured release state.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..config.hulls import Hull
from ..errors import BadIdentificationInput, IdentificationError, InputError
from ..ident.base import EstimatorMixin
from ..ident.derived import (
    b_eq,
    delta_method,
    equivalent_frequency,
    linear_stiffness,
    tested_amplitudes_deg,
)
from ..ident.output_error import OutputErrorFit
from ..physics.ikeda import linear_quadratic_fit
from ..physics.models import canonical_order
from ..physics.terms import RESTORING_TERMS
from ..records import DecayRun
from .agreement import DampingPoint, PeriodPoint, differs_sentence, period_check
from .components import ComponentScaling, component_scalings
from .correction import Correction, correction
from .effects import (
    HEAVE_CHANNELS,
    INCREMENTS,
    LIBRARY,
    OTHER_ROTATION_CHANNELS,
    Effect,
    EffectKind,
    measured_channel,
)
from .evidence import Evidence, coupling_evidence, friction_evidence
from .fitting import Fit, ModelSpec, RunPrediction, fit_spec
from .residuals import Diagnostics, cycle_trend
from .sim_equation import SimEquation, best_damping_form, identify_series
from .simulation import PREDICTION, SERIES, Match, Simulation, check_time_scale, match_runs
from .workflow import diagnose_fit, ringing_guess

#: Nothing is missing once the gap is within this multiple of what a model fitted to the measurement leaves.
FLOOR_FACTOR = 1.5
#: A step must close at least this fraction of the gap left above that floor, and pass the BIC margin.
MIN_CLOSED, DELTA_BIC = 0.25, -10.0
#: A series' equation reproducing it worse than this fraction of its amplitude (RMS) is warned about.
SERIES_FIT_LIMIT = 0.05
#: Terms that take energy out of the motion: a negative one in a fit is not physical.
DISSIPATIVE = ("b1", "b2", "b3", "fc")
#: A step must also predict held-out data better: fitted to this first part of every run, the model from
#: the measured release must be closer on the rest than the model before the step (fitted alike).
FIT_FRACTION = 0.6
#: Effects a comparison may add: increments of terms the simulation holds, then the library's.
CANDIDATES: tuple[Effect, ...] = (*INCREMENTS, *(e for e in LIBRARY if e.kind != EffectKind.TRUNCATION))


@dataclass
class CorrectionStep:
    """One effect added to the simulation: only its term(s) fitted, the simulation's own ones fixed."""

    effect: Effect
    after: Fit
    fixed: dict[str, float]  # what stayed at the simulation's values
    added: dict[str, float]  # the increments (value fitted minus the simulation's, or the new term)
    delta_bic: float
    rms_before_rad: float
    rms_after_rad: float


def _cold_fit(runs: list[DecayRun], spec: ModelSpec, fixed: dict[str, float]) -> Fit | None:
    """``spec`` fitted from the measurement's own equation-error start (the simulation's terms held)."""
    try:
        return fit_spec(runs, spec, fixed=fixed)
    except BadIdentificationInput:
        return None


def _better(first: Fit | None, second: Fit | None) -> Fit | None:
    """The fit of the two with the lower BIC (either may have failed)."""
    fits = [fit for fit in (first, second) if fit is not None]
    return min(fits, key=lambda fit: fit.bic) if fits else None


def _simplest_best(steps: list[CorrectionStep]) -> CorrectionStep | None:
    """The step that closes most of the gap, unless it is a new effect and a change of a term the
    simulation holds (its b1 or c1) fits within the BIC margin of it: then that change, the simpler
    account (a simulation whose stiffness is off is not missing a GZ curve or another motion)."""
    if not steps:
        return None
    best = min(steps, key=lambda step: step.rms_after_rad)
    held = [step for step in steps if step.effect in INCREMENTS]
    if best.effect in INCREMENTS or not held:
        return best
    simplest = min(held, key=lambda step: step.after.bic)
    return simplest if simplest.after.bic < best.after.bic - DELTA_BIC else best


def _text(coefficients: Mapping[str, float]) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in coefficients.items())


def total_b_eq(coefficients: Mapping[str, float], amplitude: float) -> float:
    """B_eq (1/s) at amplitude phi_a (rad) with Coulomb friction's share, 4 fc / (pi omega phi_a) (equal
    energy per cycle: friction takes 4 fc phi_a, linear damping pi b omega phi_a^2)."""
    value = b_eq(coefficients, amplitude)
    if coefficients.get("fc"):
        value += (
            4.0 * coefficients["fc"] / (math.pi * equivalent_frequency(coefficients, amplitude) * amplitude)
        )
    return value


def damping_band(
    coefficients: Mapping[str, float], covariance: np.ndarray, amplitudes_deg: Sequence[float]
) -> list[tuple[float, float]]:
    """``total_b_eq`` and its delta-method standard deviation at each amplitude (deg)."""
    out = []
    for a_deg in amplitudes_deg:
        fn = partial(total_b_eq, amplitude=math.radians(a_deg))
        out.append((fn(coefficients), delta_method(fn, coefficients, covariance)))
    return out


def from_release(
    fit: Fit, runs: Sequence[DecayRun], states: Sequence[tuple[float, float]]
) -> list[RunPrediction]:
    """The fitted model simulated over each run from the given release state (angle, rate)."""
    out = []
    for r, (run, state) in enumerate(zip(runs, states, strict=True)):
        angle, rate = fit.estimator.predict(run, run_index=r, initial_state=state)
        residual_rate = None if run.rate is None else run.rate - rate
        out.append(RunPrediction(run.name, run.t, angle, rate, run.angle - angle, residual_rate))
    return out


def rms_rad(curves: Sequence[RunPrediction]) -> float:
    """RMS of the angle residual over every sample of every run."""
    return float(np.sqrt(np.mean(np.concatenate([c.residual_angle for c in curves]) ** 2)))


class SimulationComparison(EstimatorMixin):
    """Compare a simulation with measured decays, name what it misses, add it, show the gap shrink.

    Fitted: ``matches_`` (series), ``runs_`` (the measured runs compared), ``equation_``
    (``SimEquation``), ``reference_`` (the measured side's fit), ``release_states_``,
    ``amplitudes_deg_``, ``damping_`` (``DampingPoint`` per amplitude), ``periods_s_``
    ({measured, simulation, corrected}: median cycle period of each curve), ``period_error_``,
    ``disagrees_in_`` ("damping", "stiffness"), ``diagnostics_`` (the simulation's residual),
    ``simulation_fit_``, ``steps_``, ``corrected_``, ``free_``, ``curves_`` and ``rms_rad_``
    ({measured model, simulation, corrected, free refit}), ``gap_reduction_``, ``verdict_``,
    ``component_changes_`` (a prediction's parts that would have to change to meet the measurement).
    """

    def __init__(
        self,
        simulation: Simulation,
        max_steps: int = 3,
        hull: Hull | None = None,
        progress: Callable[[str], None] | None = None,
    ):
        self.simulation = simulation
        self.max_steps = max_steps
        self.hull = hull
        self.progress = progress

    def _say(self, label: str) -> None:
        if self.progress is not None:
            self.progress(label)

    def fit(self, runs: Sequence[DecayRun]) -> SimulationComparison:
        if not runs:
            raise BadIdentificationInput("no measured decay runs to compare with")
        if self.max_steps < 0:
            raise InputError(f"--max-steps must be 0 or more, not {self.max_steps}")
        axes = {run.axis for run in runs} | {run.axis for run in self.simulation.runs}
        if len(axes) > 1:
            raise BadIdentificationInput(f"runs mix axes {sorted(axes)}; compare one axis at a time")
        runs = self._matched(list(runs))
        self.runs_ = runs
        self.reference_ = self._measured_model(runs)
        self.release_states_ = list(self.reference_.initial_states_)
        self.equation_ = self._equation()
        sim = self.equation_.coefficients
        spec = ModelSpec(terms=canonical_order(tuple(sim)))
        self._say("simulation from the measured release")
        self.simulation_fit_ = fit_spec(runs, spec, fixed=dict(sim))
        self.diagnostics_: Diagnostics = diagnose_fit(self.simulation_fit_, runs)
        self.steps_ = self._correct(runs)
        self.corrected_ = self.steps_[-1].after if self.steps_ else self.simulation_fit_
        self._say("free refit")
        self.free_ = fit_spec(runs, self.corrected_.spec, start=self.corrected_)
        self._compare_curves(runs)
        self._compare_cycles(runs)
        # each term as the corrected model ends with it, less the simulation's own: a term freed or added
        # by one step is refitted by the later ones, so a step's own figure can be stale
        final = self.corrected_.coefficients
        self.added_: dict[str, float] = {
            term: final[term] - sim.get(term, 0.0) for step in self.steps_ for term in step.added
        }
        stiffness = linear_stiffness(self.reference_.coefficients_)
        self.correction_: Correction = correction(self.added_, stiffness, self.hull, runs[0].axis)
        self.scalings_: list[ComponentScaling] = component_scalings(
            self.simulation.shares, sim, final, list(self.added_), math.sqrt(max(stiffness, 1e-12)),
            math.radians(max(self.amplitudes_deg_)), self.correction_,
        )  # fmt: skip
        self.differs_ = (
            differs_sentence(
                self.damping_, "prediction" if self.simulation.kind == PREDICTION else "simulation"
            )
            if self.withheld_ and self.damping_
            else None
        )
        self.component_changes_ = self._component_changes()
        self.warnings_ = self._warnings()
        self.verdict_ = self._verdict()
        return self

    def _measured_model(self, runs: list[DecayRun]) -> OutputErrorFit:
        """The measurement's own model for B_eq and the release states (``best_damping_form``)."""
        self._say("measured model")
        return best_damping_form(runs)

    def _matched(self, runs: list[DecayRun]) -> list[DecayRun]:
        """The measured runs a series has a match for (all of them for a model)."""
        self.matches_: list[Match] = []
        self.unmatched_: list[str] = []
        if self.simulation.kind != SERIES:
            return runs
        simulated = list(self.simulation.runs)
        check_time_scale(runs, simulated)
        self.matches_ = match_runs(runs, simulated)
        names = {m.measured for m in self.matches_}
        self.unmatched_ = [run.name for run in runs if run.name not in names]
        used = list(dict.fromkeys(m.simulated for m in self.matches_))
        self._series_runs = [next(r for r in simulated if r.name == name) for name in used]
        return [run for run in runs if run.name in names]

    def _equation(self) -> SimEquation:
        if self.simulation.kind == SERIES:
            self._say("the simulation's equation")
            return identify_series(self._series_runs)
        coefficients = dict(self.simulation.coefficients)
        if self.simulation.kind == PREDICTION:  # a damping prediction: its restoring is the measured one
            measured = self.reference_.coefficients_
            coefficients = {k: v for k, v in coefficients.items() if k not in RESTORING_TERMS}
            coefficients |= {k: v for k, v in measured.items() if k in RESTORING_TERMS}
        if not {"c1", "s1"} & set(coefficients):
            raise BadIdentificationInput(
                f"simulation {self.simulation.name} has no linear restoring (c1 or s1)"
            )
        terms = canonical_order(tuple(coefficients))
        ordered = {t: coefficients[t] for t in terms}
        return SimEquation(terms, ordered, np.zeros((len(terms), len(terms))), None)

    def _gap(self, fit: Fit, runs: list[DecayRun]) -> float:
        """RMS of the angle over the measured decays, the model simulated from the measured release."""
        return rms_rad(from_release(fit, runs, self.release_states_))

    def _correct(self, runs: list[DecayRun]) -> list[CorrectionStep]:
        """Add effects one at a time while the gap is above the floor and a step closes a real part of it."""
        floor = float(np.sqrt(np.mean(np.concatenate([r["angle"] for r in self.reference_.residuals_]) ** 2)))
        self.floor_rad_ = floor
        self.evidence_ = self._evidence(runs)
        self.withheld_: dict[str, str] = {}
        current, fixed = self.simulation_fit_, dict(self.equation_.coefficients)
        gap = self._gap(current, runs)
        steps: list[CorrectionStep] = []
        while len(steps) < self.max_steps and gap > FLOOR_FACTOR * floor:
            diag = diagnose_fit(current, runs)
            tried = [self._try(effect, current, fixed, runs, diag, (gap, floor)) for effect in CANDIDATES]
            best = _simplest_best([step for step in tried if step is not None])
            if best is None:
                break
            steps.append(best)
            current, fixed, gap = best.after, best.fixed, best.rms_after_rad
        return steps

    def _try(
        self,
        effect: Effect,
        current: Fit,
        fixed: dict[str, float],
        runs: list[DecayRun],
        diag: Diagnostics,
        gaps: tuple[float, float],
    ) -> CorrectionStep | None:
        """``effect`` added to the current model, only its term(s) fitted; None unless it closes
        ``MIN_CLOSED`` of the gap above the floor (``gaps``: now, floor) and passes the BIC margin."""
        spec = effect.extend(current.spec, runs, diag)
        evidence = self.evidence_.get(effect.key)
        if spec is not None and evidence is not None and not evidence.seen:
            self.withheld_[effect.name] = evidence.line  # it may fit, but nothing says it is there
            return None
        freed, held = fixed, None  # held: a term of the simulation's this effect frees (its b1 or c1)
        if spec is None:
            if effect.increments not in fixed:
                return None
            held = effect.increments
            spec, freed = current.spec, {k: v for k, v in fixed.items() if k != held}
        self._say(effect.name)
        try:
            after = fit_spec(runs, spec, start=current, guess=ringing_guess(diag), fixed=freed)
        except BadIdentificationInput:
            after = None  # the candidate diverged from here
        if held is not None:  # from the simulation's value, a period far off wraps the phase (a local
            after = _better(after, _cold_fit(runs, spec, freed))  # minimum): from the data's start too
        if after is None:
            return None  # it is not what is missing
        new = {k: v for k, v in after.coefficients.items() if k not in current.coefficients}
        if not effect.plausible(after) or any(v < 0 for k, v in new.items() if k in ("b2", "b3")):
            return None
        delta_bic = after.bic - current.bic
        gap, floor = gaps
        gap_after = self._gap(after, runs)
        closes = gap - gap_after >= MIN_CLOSED * (gap - floor)  # False for a diverging candidate (NaN)
        if (
            delta_bic >= DELTA_BIC
            or not closes
            or not self._predicts_held_out((current, fixed), (after, freed), runs)
        ):
            return None
        added = dict(new)
        if any(after.coefficients.get(k, 0.0) < 0 for k in DISSIPATIVE):
            return None  # a damping that feeds energy in: no component is scaled below zero, none traded off
        if held is not None:
            added[held] = after.coefficients[held] - fixed[held]
        return CorrectionStep(effect, after, freed, added, delta_bic, gap, gap_after)

    def _evidence(self, runs: list[DecayRun]) -> dict[str, Evidence]:
        """What the measurement shows of the effects only their own signature may name (``evidence``)."""
        omega = math.sqrt(max(linear_stiffness(self.reference_.coefficients_), 1e-12))
        return {
            "friction.coulomb": friction_evidence(runs),
            "coupling.heave": coupling_evidence(runs, measured_channel(runs, HEAVE_CHANNELS), omega),
            "coupling.other_rotation": coupling_evidence(
                runs, measured_channel(runs, OTHER_ROTATION_CHANNELS), omega
            ),
            "coupling.unmeasured": Evidence(False, "no channel of the other motion is recorded to name it"),
        }

    def _held_out_rms(self, fit: Fit, fixed: dict[str, float], runs: list[DecayRun]) -> float:
        """``fit``'s model refitted to the first ``FIT_FRACTION`` of every run (``fixed`` held), from the
        measured release: the angle's RMS over the rest."""
        first = [run.window(0, int(FIT_FRACTION * run.t.size)) for run in runs]
        try:
            part = fit_spec(first, fit.spec, start=fit, fixed=fixed)
        except BadIdentificationInput:
            return math.inf
        curves = from_release(part, runs, self.release_states_)
        rest = [c.residual_angle[int(FIT_FRACTION * c.t.size) :] for c in curves]
        return float(np.sqrt(np.mean(np.concatenate(rest) ** 2)))

    def _predicts_held_out(
        self, before: tuple[Fit, dict[str, float]], after: tuple[Fit, dict[str, float]], runs: list[DecayRun]
    ) -> bool:
        """Chosen on held-out data, as the workflow's effects are: the step (a fit and the terms it holds)
        predicts the rest of every run better from a fit to its first part."""
        return self._held_out_rms(*after, runs) < self._held_out_rms(*before, runs)

    def _compare_curves(self, runs: list[DecayRun]) -> None:
        states = self.release_states_
        measured_model = Fit(ModelSpec(terms=self.reference_.terms_), self.reference_)
        fits = {
            "measured model": measured_model,
            "simulation": self.simulation_fit_,
            "corrected": self.corrected_,
            "free refit": self.free_,
        }
        self.curves_ = {name: from_release(fit, runs, states) for name, fit in fits.items()}
        self.rms_rad_ = {name: rms_rad(curves) for name, curves in self.curves_.items()}
        diverged = [name for name, value in self.rms_rad_.items() if not math.isfinite(value)]
        if diverged:
            raise IdentificationError(
                f"the {' and '.join(diverged)} model does not stay finite from the measured release: "
                f"check the simulation's equation ({_text(self.equation_.coefficients)})"
            )
        self.gap_reduction_ = 1.0 - self.rms_rad_["corrected"] / self.rms_rad_["simulation"]

    def _compare_cycles(self, runs: list[DecayRun]) -> None:
        self.amplitudes_deg_ = tested_amplitudes_deg(runs, self.reference_.offsets_)
        corrected = self.corrected_.estimator
        sides = [
            damping_band(self.reference_.coefficients_, self.reference_.covariance_, self.amplitudes_deg_),
            damping_band(self.equation_.coefficients, self.equation_.covariance, self.amplitudes_deg_),
            damping_band(corrected.coefficients_, corrected.covariance_, self.amplitudes_deg_),
        ]
        self.damping_ = [
            DampingPoint(a, *points) for a, *points in zip(self.amplitudes_deg_, *sides, strict=True)
        ]
        omega0 = math.sqrt(max(self.reference_.coefficients_["c1"], 1e-6))
        measured_trend = cycle_trend([r.t for r in runs], [r.angle for r in runs], omega0)
        self.trends_ = {"measured": measured_trend}
        for name in ("simulation", "corrected"):
            curves = self.curves_[name]
            self.trends_[name] = cycle_trend([c.t for c in curves], [c.angle for c in curves], omega0)
        self.cycle_periods_s_ = {
            name: float(np.median(trend.period_s)) if trend.period_s.size else math.nan
            for name, trend in self.trends_.items()
        }
        models = {
            "measured": self.reference_.coefficients_,
            "simulation": self.equation_.coefficients,
            "corrected": self.corrected_.estimator.coefficients_,
        }
        self.periods_ = [
            PeriodPoint(a, *(2 * math.pi / equivalent_frequency(c, math.radians(a)) for c in models.values()))
            for a in self.amplitudes_deg_
        ]
        self.period_check_ = period_check(measured_trend, self.equation_.coefficients)
        self.disagrees_in_ = tuple(
            name
            for name, off in (
                ("damping", any(p.disagrees for p in self.damping_)),
                # a prediction's stiffness is the measured one (it predicts damping): nothing to disagree
                ("stiffness", self.period_check_.disagrees and self.simulation.kind != PREDICTION),
            )
            if off
        )

    def _component_changes(self) -> list[str]:
        """A prediction's account of the measured damping: its parts that would have to change, by how much.

        The measured B_eq over the tested amplitudes is put in the prediction's own form,
        b1 + 8/(3 pi) omega phi_a b2 (least squares), and handed to the prediction.
        """
        explain = self.simulation.component_changes
        if explain is None or len(self.damping_) < 2:
            return []
        omega = math.sqrt(max(linear_stiffness(self.reference_.coefficients_), 1e-12))
        amplitudes = np.radians([point.amplitude_deg for point in self.damping_])
        b1, b2 = linear_quadratic_fit(omega, amplitudes, [point.measured[0] for point in self.damping_])
        return explain(b1, b2, list(amplitudes))

    def _warnings(self) -> list[str]:
        """What physics or the inputs say not to trust: shown wherever the comparison is."""
        out = [
            f"measured run {name} has no simulated run near its initial angle: not compared"
            for name in self.unmatched_
        ]
        eq = self.equation_
        if eq.series_rms_rad is not None and self.simulation.runs:
            top = max(float(np.max(np.abs(run.angle))) for run in self._series_runs)
            if eq.series_rms_rad > SERIES_FIT_LIMIT * top:
                out.append(
                    "the simulation's equation reproduces its series only to "
                    f"{math.degrees(eq.series_rms_rad):.3g} deg RMS "
                    f"({100 * eq.series_rms_rad / top:.0f} % of its amplitude): "
                    "what is compared is that equation"
                )
        for label, fit in (("corrected", self.corrected_), ("free refit", self.free_)):
            negative = [f"{k} = {v:.4g}" for k, v in fit.coefficients.items() if k in DISSIPATIVE and v < 0]
            if negative:
                out.append(
                    f"{label}: {', '.join(negative)} < 0 is not physical (a damping that feeds energy in): "
                    "its free terms trade off against each other"
                )
        return out

    def _verdict(self) -> str:
        before, after = (math.degrees(self.rms_rad_[k]) for k in ("simulation", "corrected"))
        floor = math.degrees(self.floor_rad_)
        if not self.steps_:
            if self.rms_rad_["simulation"] > FLOOR_FACTOR * self.floor_rad_:
                return (
                    f"the simulation misses something outside the library: RMS {before:.3f} deg against "
                    f"{floor:.3f} deg for a model fitted to the measurement"
                )
            differs = " and ".join(self.disagrees_in_)
            return (
                f"nothing missing: the simulation follows the measurement (RMS {before:.3f} deg) within "
                f"{FLOOR_FACTOR:g} times what a model fitted to it leaves ({floor:.3f} deg)"
                + (f", although its {differs} differs beyond the intervals" if differs else "")
            )
        scaled = {s.term for s in self.scalings_}
        named = [f"{s.verdict_word}: {s.label}, {s.times_measured:.2g}x the measured" for s in self.scalings_]
        missing = [f"{s.effect.name} ({s.effect.family})" for s in self.steps_ if not set(s.added) <= scaled]
        names = "; ".join(([f"missing: {'; '.join(missing)}"] if missing else []) + named)
        return (
            f"{names}; gap (RMS of the angle, simulation vs measured) "
            f"{before:.3f} -> {after:.3f} deg, reduced by {100 * self.gap_reduction_:.0f} %"
        )
