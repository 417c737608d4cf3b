"""The library of physical effects a decay model may be missing.

Every entry has a physical name, a family (what tests and reports commit to:
quadratic and cubic damping are nearly interchangeable over one decay, the
family "amplitude-dependent damping" is not), what it adds to the model, and
the signature it leaves in the residual of a model that lacks it. Measurement
errors change the observation equation, not the equation of motion; a late
disturbance (reflected tank waves) is cut off, not modelled.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from ..records import DecayRun
from .fitting import Fit, ModelSpec
from .residuals import Diagnostics, swing_frequency

#: What a candidate is added from: the current model, the records, and what the residual says.
Extend = Callable[[ModelSpec, Sequence[DecayRun], Diagnostics], ModelSpec | None]

#: Measured channels a coupling term may use, by the motion they carry.
#: Names as DecayRun.channels holds them: CSV import strips _deg/_rad after converting to rad, MCAP
#: recordings name the other axis (``other_angle_pitch``), the KVLCC2 tracking files have z, theta, phi.
HEAVE_CHANNELS: tuple[str, ...] = ("heave_m", "heave", "z", "acc_z_m_s2")
OTHER_ROTATION_CHANNELS: tuple[str, ...] = (
    "other_angle",
    "other_angle_pitch",
    "other_angle_roll",
    "theta",
    "phi",
    "pitch",
    "roll",
)


class Family(StrEnum):
    """What tests and reports commit to: effects of one family are nearly interchangeable over a decay."""

    AMPLITUDE_DAMPING = "amplitude-dependent damping"
    NONLINEAR_RESTORING = "nonlinear restoring"
    OFFSET_OR_ASYMMETRY = "offset or asymmetry"
    MEASUREMENT_ERROR = "measurement error"
    DRY_FRICTION = "dry friction"
    COUPLED_MOTION = "coupled motion"
    LATE_DISTURBANCE = "late-time disturbance"
    LINEAR_DAMPING = "linear damping"
    STIFFNESS = "stiffness"


class EffectKind(StrEnum):
    """Where an effect acts: the equation of motion, the observation equation, or the record's length."""

    DYNAMICS = "dynamics"
    OBSERVATION = "observation"
    TRUNCATION = "truncation"


@dataclass(frozen=True)
class Effect:
    """One candidate: what it is, what it adds, what its absence looks like."""

    key: str
    name: str
    family: Family
    adds: str  # the term(s) in words and symbols
    signature: str  # what the residual of a model without it shows
    kind: EffectKind
    apply: Extend
    #: A parameter that must stay >= 0 for the fit to mean this effect (friction cannot feed energy in).
    non_negative: str | None = None
    #: A frequency parameter that must stay off the frequency the measured angle swings at (+-15 %): a ring
    #: there is the roll itself mis-modelled (a simulation whose period is off), not another motion.
    off_swing: str | None = None
    #: The term whose value this effect changes when a model holds it already (a simulation's b2 too small).
    increments: str | None = None
    #: What its absence says about the physics (a simulation that misses it leaves out this).
    physics: str = ""

    def extend(self, spec: ModelSpec, runs: Sequence[DecayRun], diag: Diagnostics) -> ModelSpec | None:
        """The model with this effect added, or None when it is present already or cannot be fitted here."""
        return self.apply(spec, runs, diag)

    def plausible(self, fit: Fit) -> bool:
        """Whether the refit describes this effect physically (else it is fitting something else)."""
        if self.non_negative is not None and fit.coefficients[self.non_negative] < 0.0:
            return False
        return self.off_swing is None or not _on_measured_swing(fit.coefficients[self.off_swing], fit)


def _on_measured_swing(omega_rad_s: float, fit: Fit) -> bool:
    """Whether ``omega_rad_s`` is within 15 % of the frequency the measured angles swing at."""
    measured = [p.angle + p.residual_angle for p in fit.runs]
    rate_hz = 1.0 / float(np.median(np.diff(fit.runs[0].t)))
    return abs(omega_rad_s / swing_frequency(measured, rate_hz) - 1.0) <= SWING_BAND


#: How near the measured swing a ringing frequency is the swing itself (the band ``ringing_frequency``
#: leaves out around the natural frequency).
SWING_BAND = 0.15


#: What an amplitude-dependent damping a simulation lacks is, physically.
VISCOUS = "viscous roll damping: eddy making at the bilges, bilge keels (what potential flow leaves out)"


def _add_term(term: str) -> Extend:
    def apply(spec: ModelSpec, _runs: Sequence[DecayRun], _diag: Diagnostics) -> ModelSpec | None:
        return None if term in spec.terms else spec.with_(terms=(*spec.terms, term))

    return apply


def _sine_restoring(spec: ModelSpec, _runs: Sequence[DecayRun], _diag: Diagnostics) -> ModelSpec | None:
    """Replace the linear spring c1*x by a wall-sided GZ s1*sin(x) (same number of parameters)."""
    if "c1" not in spec.terms or "s1" in spec.terms:
        return None
    return spec.with_(terms=tuple("s1" if t == "c1" else t for t in spec.terms))


def _set_flag(flag: str, needs_rate: bool) -> Extend:
    def apply(spec: ModelSpec, runs: Sequence[DecayRun], _diag: Diagnostics) -> ModelSpec | None:
        if getattr(spec, flag) or (needs_rate and any(r.rate is None for r in runs)):
            return None
        return spec.with_(**{flag: True})

    return apply


def measured_channel(runs: Sequence[DecayRun], candidates: Sequence[str]) -> str | None:
    """The first of ``candidates`` measured in every run."""
    return next((ch for ch in candidates if all(ch in r.channels for r in runs)), None)


def _couple(candidates: tuple[str, ...]) -> Extend:
    def apply(spec: ModelSpec, runs: Sequence[DecayRun], _diag: Diagnostics) -> ModelSpec | None:
        channel = measured_channel(runs, candidates)
        if channel is None or channel in spec.coupling:
            return None
        return spec.with_(coupling=(*spec.coupling, channel))

    return apply


def _ringing(spec: ModelSpec, runs: Sequence[DecayRun], diag: Diagnostics) -> ModelSpec | None:
    """Only when the residual rings at a non-harmonic frequency and no measured channel can explain it."""
    measured = measured_channel(runs, HEAVE_CHANNELS + OTHER_ROTATION_CHANNELS)
    if spec.ring or spec.coupling or measured is not None or diag.ringing_rad_s is None:
        return None
    return spec.with_(ring=True)


def _held(_spec: ModelSpec, _runs: Sequence[DecayRun], _diag: Diagnostics) -> ModelSpec | None:
    """A term every model holds (b1, c1): only its value can be missing (``Effect.increments``)."""
    return None


def _never(_spec: ModelSpec, _runs: Sequence[DecayRun], _diag: Diagnostics) -> ModelSpec | None:
    """Truncation is not a model change; the workflow handles it by cutting the records."""
    return None


LIBRARY: tuple[Effect, ...] = (
    Effect(
        "damping.quadratic",
        "quadratic damping",
        Family.AMPLITUDE_DAMPING,
        "b2*|x'|x'",
        "damping ratio grows linearly with amplitude; envelope under-damped early, over-damped late",
        EffectKind.DYNAMICS,
        _add_term("b2"),
        increments="b2",
        physics=VISCOUS,
    ),
    Effect(
        "damping.cubic",
        "cubic damping",
        Family.AMPLITUDE_DAMPING,
        "b3*x'^3",
        "damping ratio grows with amplitude squared; envelope mismatch like quadratic damping",
        EffectKind.DYNAMICS,
        _add_term("b3"),
        increments="b3",
        physics=VISCOUS,
    ),
    Effect(
        "restoring.cubic",
        "cubic restoring",
        Family.NONLINEAR_RESTORING,
        "c3*x^3",
        "period changes with amplitude; phase drift growing along the decay; residual peak at 3w",
        EffectKind.DYNAMICS,
        _add_term("c3"),
        increments="c3",
        physics="a restoring nonlinearity: the GZ curve away from its initial slope (flare, deck edge)",
    ),
    Effect(
        "restoring.sine",
        "GZ-like sine restoring",
        Family.NONLINEAR_RESTORING,
        "s1*sin(x) instead of c1*x",
        "period grows with amplitude (softening); phase drift growing along the decay",
        EffectKind.DYNAMICS,
        _sine_restoring,
        physics="a restoring nonlinearity: a wall-sided GZ curve",
    ),
    Effect(
        "sensor.offset",
        "angle offset",
        Family.OFFSET_OR_ASYMMETRY,
        "per-run offset in y = x + b",
        "residual mean not zero; peak near zero frequency; unequal positive and negative peaks",
        EffectKind.OBSERVATION,
        _set_flag("offset", needs_rate=False),
        physics="a heel of the model or a zero error of the sensor",
    ),
    Effect(
        "restoring.asymmetric",
        "asymmetric restoring",
        Family.OFFSET_OR_ASYMMETRY,
        "c2*x^2",
        "mean shift that shrinks with amplitude; residual peak at 2w and near zero",
        EffectKind.DYNAMICS,
        _add_term("c2"),
        increments="c2",
        physics="an asymmetric hull or loading (a list, an off-centre weight)",
    ),
    Effect(
        "sensor.gyro_bias",
        "gyro bias",
        Family.MEASUREMENT_ERROR,
        "rate y = x' + b_gyro",
        "rate residual has a non-zero mean",
        EffectKind.OBSERVATION,
        _set_flag("gyro_bias", needs_rate=True),
        physics="the gyro's bias: a measurement error",
    ),
    Effect(
        "sensor.lag",
        "sensor time lag",
        Family.MEASUREMENT_ERROR,
        "angle y = x(t - tau)",
        "angle residual proportional to the rate (quarter period out of phase with the angle)",
        EffectKind.OBSERVATION,
        _set_flag("lag", needs_rate=True),
        physics="the sensor's filter lag: a measurement error",
    ),
    Effect(
        "sensor.gain",
        "sensor gain error",
        Family.MEASUREMENT_ERROR,
        "angle y = (1 + g) x",
        "angle residual proportional to the angle itself",
        EffectKind.OBSERVATION,
        _set_flag("gain", needs_rate=True),
        physics="the sensor's scale: a measurement error",
    ),
    Effect(
        "friction.coulomb",
        "Coulomb friction of the rig",
        Family.DRY_FRICTION,
        "fc*tanh(x'/eps)",
        "decrement per half cycle tends to a constant at small amplitude; straight-line envelope; "
        "damping ratio falls with amplitude",
        EffectKind.DYNAMICS,
        _set_flag("coulomb", needs_rate=False),
        non_negative="fc",
        physics="dry friction of the rig (gimbals, cables): not the ship's, keep it out of its damping",
    ),
    Effect(
        "coupling.heave",
        "coupling with heave",
        Family.COUPLED_MOTION,
        "k*z(t) with z the measured heave",
        "residual peak at the heave frequency; residual correlated with the measured heave",
        EffectKind.DYNAMICS,
        _couple(HEAVE_CHANNELS),
        physics="a coupled heave motion the simulation does not have",
    ),
    Effect(
        "coupling.other_rotation",
        "coupling with the other rotation",
        Family.COUPLED_MOTION,
        "k*theta(t) with theta the measured other rotation",
        "residual peak at the other axis' frequency; residual correlated with the measured other angle",
        EffectKind.DYNAMICS,
        _couple(OTHER_ROTATION_CHANNELS),
        physics="a coupled pitch or roll motion the simulation does not have",
    ),
    Effect(
        "coupling.unmeasured",
        "coupling with an unmeasured motion",
        Family.COUPLED_MOTION,
        "exp(-l t) (p cos wt + q sin wt), w and l shared, p and q per run",
        "residual peak at a frequency that is no harmonic of the natural one, and no measured channel",
        EffectKind.DYNAMICS,
        _ringing,
        non_negative="ring_decay_1_s",  # a motion released with the model rings down; a growing one is later
        off_swing="ring_omega_rad_s",
        physics="a motion the simulation does not have (sloshing, the rig, another mode)",
    ),
    Effect(
        "disturbance.late",
        "reflected tank waves arriving late",
        Family.LATE_DISTURBANCE,
        "nothing: the records are cut before the disturbance arrives",
        "residual near noise level early, then a burst after the reflection time",
        EffectKind.TRUNCATION,
        _never,
        physics="the tank: reflected waves (no model term; cut the record before them)",
    ),
)

#: Effects only a model that holds the term already can miss: a simulation whose linear damping or
#: stiffness is off. The workflow's baselines always fit these, so they are not in ``LIBRARY``.
INCREMENTS: tuple[Effect, ...] = (
    Effect(
        "damping.linear",
        "linear damping",
        Family.LINEAR_DAMPING,
        "more (or less) b1*x'",
        "damping ratio off by the same amount at every amplitude; envelope off from the first cycle",
        EffectKind.DYNAMICS,
        _held,
        increments="b1",
        physics="linear damping: skin friction or wave radiation (or dry friction of the rig)",
    ),
    Effect(
        "restoring.linear",
        "stiffness",
        Family.STIFFNESS,
        "another c1*x",
        "period off at every amplitude; phase drift growing linearly along the decay",
        EffectKind.DYNAMICS,
        _held,
        increments="c1",
        physics="the stiffness: GM (or displacement, or the roll inertia the period implies) differs",
    ),
)

EFFECTS: dict[str, Effect] = {e.key: e for e in LIBRARY}
FAMILIES: tuple[Family, ...] = tuple(dict.fromkeys(e.family for e in LIBRARY))
