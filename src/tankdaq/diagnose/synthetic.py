"""Known-truth decay sets with hidden effects, to prove the workflow finds what is missing.

A reference simulation independent of the fitting engine (ODEPACK's LSODA, tight
tolerance, the forcing as exact functions of time), several release angles so
amplitude effects show, and sensor noise of an MTi-class IMU (0.06 deg on the
angle, 0.1 deg/s on the gyro). Each effect's size is drawn at random from a
realistic band, so repeated draws test the workflow, not one lucky case.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..physics.decay import integrate_reference, simulate_decay, terms_sum
from ..physics.ikeda import IkedaPrediction
from ..records import DecayRun
from .components import prediction_shares
from .effects import EFFECTS
from .fitting import COULOMB_EPS_RAD_S

NOISE_ANGLE_RAD = 0.001
NOISE_RATE_RAD_S = 0.002
NOISE_HEAVE_M = 1e-4
HEAVE_PER_ANGLE_M_RAD = 0.05  # heave excited at release, per rad of release angle
OTHER_PER_ANGLE = 0.3  # other rotation excited at release, per unit release angle


@dataclass
class SyntheticSet:
    """Runs plus the truth they were made from (parameter names as the fits report them)."""

    runs: list[DecayRun]
    effects: tuple[str, ...]
    truth: dict[str, float]
    noise_angle_rad: float
    noise_rate_rad_s: float
    onset_s: float | None = None  # arrival of the late disturbance, if hidden


def _draw_truth(effects: Sequence[str], rng: np.random.Generator) -> dict[str, float]:
    period_s = rng.uniform(1.6, 2.4)
    omega0 = 2 * np.pi / period_s
    c1 = omega0**2
    truth = {"b1": 2 * rng.uniform(0.02, 0.04) * omega0, "c1": c1}
    sign = rng.choice([-1.0, 1.0])

    def heave() -> dict[str, float]:
        return {"k_heave_m": sign * c1 * rng.uniform(1.2, 2.4), "heave_omega": omega0 * rng.uniform(1.6, 2.2)}

    draws: dict[str, Callable[[], dict[str, float]]] = {
        "damping.quadratic": lambda: {"b2": rng.uniform(0.2, 0.4)},
        "damping.cubic": lambda: {"b3": rng.uniform(0.3, 0.6)},
        "restoring.cubic": lambda: {"c3": sign * c1 * rng.uniform(0.6, 1.2)},
        "restoring.sine": lambda: {"s1": truth.pop("c1")},
        "sensor.offset": lambda: {"angle_offset_rad": sign * rng.uniform(0.005, 0.015)},
        "restoring.asymmetric": lambda: {"c2": sign * c1 * rng.uniform(0.3, 0.6)},
        "sensor.gyro_bias": lambda: {"gyro_bias_rad_s": sign * rng.uniform(0.01, 0.03)},
        "sensor.lag": lambda: {"angle_lag_s": rng.uniform(0.02, 0.06)},
        "sensor.gain": lambda: {"angle_gain_error": sign * rng.uniform(0.04, 0.1)},
        "friction.coulomb": lambda: {"fc": rng.uniform(0.01, 0.03)},
        "coupling.heave": heave,
        # the same heave, not recorded: its frequency is what the workflow can measure
        "coupling.unmeasured": lambda: {**(h := heave()), "ring_omega_rad_s": h["heave_omega"]},
        "coupling.other_rotation": lambda: {
            "k_other_angle": sign * c1 * rng.uniform(0.2, 0.4),
            "other_omega": omega0 * rng.uniform(1.3, 1.8),
        },
        "disturbance.late": lambda: {
            "wave_force": c1 * rng.uniform(0.002, 0.004),
            "onset_s": rng.uniform(8.0, 11.0),
        },
    }
    for effect in effects:
        if effect not in draws:
            raise InputError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
        truth.update(draws[effect]())
    return truth


def _damped_cosine(
    amplitude: float, omega: float, zeta: float, phase: float
) -> Callable[[np.ndarray], np.ndarray]:
    """A motion released together with the model: another mode ringing down at its own frequency."""
    return lambda t: amplitude * np.exp(-zeta * omega * t) * np.cos(omega * t + phase)


def _forcing(
    truth: dict[str, float], angle0: float, omega0: float
) -> tuple[Callable[[float], float], dict[str, Callable[[np.ndarray], np.ndarray]]]:
    """The external forcing of the equation of motion and the measured channels it comes from."""
    channels: dict[str, Callable[[np.ndarray], np.ndarray]] = {}
    gains: dict[str, float] = {}
    if "k_heave_m" in truth:
        channels["heave_m"] = _damped_cosine(
            HEAVE_PER_ANGLE_M_RAD * abs(angle0), truth["heave_omega"], 0.1, 0.0
        )
        gains["heave_m"] = truth["k_heave_m"]
    if "k_other_angle" in truth:
        channels["other_angle"] = _damped_cosine(OTHER_PER_ANGLE * angle0, truth["other_omega"], 0.08, 0.5)
        gains["other_angle"] = truth["k_other_angle"]
    onset, wave_force = truth.get("onset_s", np.inf), truth.get("wave_force", 0.0)

    weighted = [(k, channels[name]) for name, k in gains.items()]

    def force(t: float) -> float:
        total = 0.0
        for k, channel in weighted:
            total += k * float(channel(np.asarray(t)))
        if t > onset:  # reflected waves at the radiated (natural) frequency, building up over 0.5 s
            total += wave_force * (1 - np.exp(-(t - onset) / 0.5)) * np.sin(omega0 * (t - onset))
        return total

    return force, channels


def make_decay_set(
    effects: Sequence[str] = (),
    seed: int | None = None,
    angles_deg: Sequence[float] = (24.0, 15.0, 8.0),
    duration_s: float = 15.0,
    rate_hz: float = 100.0,
    noise_angle_rad: float = NOISE_ANGLE_RAD,
    noise_rate_rad_s: float = NOISE_RATE_RAD_S,
) -> SyntheticSet:
    """Decays from each release angle (random sign), with the given effects hidden in them."""
    rng = np.random.default_rng(seed)
    truth = _draw_truth(effects, rng)
    damping_and_restoring = terms_sum(truth)
    omega0 = float(np.sqrt(truth.get("c1", 0.0) + truth.get("s1", 0.0)))
    t = np.arange(round(duration_s * rate_hz)) / rate_hz
    fc = truth.get("fc", 0.0)
    lag = truth.get("angle_lag_s", 0.0)
    runs = []
    for i, angle_deg in enumerate(angles_deg):
        angle0 = np.deg2rad(angle_deg + rng.uniform(-1, 1)) * rng.choice([-1.0, 1.0])
        force, channels = _forcing(truth, angle0, omega0)

        def rhs(tt: float, y: np.ndarray, force: Callable[[float], float] = force) -> list[float]:
            x, v = float(y[0]), float(y[1])  # plain floats: called thousands of times a decay
            friction = fc * math.tanh(v / COULOMB_EPS_RAD_S)
            return [v, -damping_and_restoring(x, v) - friction - force(tt)]

        # the lagged angle is read at t - lag (held at the release angle before 0): both grids at once
        grid, where = np.unique(np.concatenate([t, np.maximum(t - lag, 0.0)]), return_inverse=True)
        states = integrate_reference(rhs, grid, [angle0, 0.0])
        rate_true = states[where[: t.size], 1]
        angle_true = states[where[t.size :], 0]
        angle = (1 + truth.get("angle_gain_error", 0.0)) * angle_true + truth.get("angle_offset_rad", 0.0)
        rate = rate_true + truth.get("gyro_bias_rad_s", 0.0)
        measured = {
            name: f(t) + rng.normal(0.0, NOISE_HEAVE_M if name == "heave_m" else noise_angle_rad, t.size)
            for name, f in channels.items()
            if "ring_omega_rad_s" not in truth  # an unmeasured coupling leaves no channel
        }
        runs.append(
            DecayRun(
                t=t.copy(),
                angle=angle + rng.normal(0.0, noise_angle_rad, t.size),
                rate=rate + rng.normal(0.0, noise_rate_rad_s, t.size),
                name=f"synthetic-{i + 1}",
                channels=measured,
                meta={"release_angle_deg": float(np.rad2deg(angle0)), "hidden_effects": list(effects)},
            )
        )
    return SyntheticSet(
        runs=runs,
        effects=tuple(effects),
        truth=truth,
        noise_angle_rad=noise_angle_rad,
        noise_rate_rad_s=noise_rate_rad_s,
        onset_s=truth.get("onset_s"),
    )


@dataclass
class PredictionSet:
    """Decays made from a prediction's own components with one scaled, and what was scaled."""

    runs: list[DecayRun]
    component: str  # the Ikeda component scaled (``physics.ikeda.COMPONENTS`` key), "" for none
    factor: float
    speed_m_s: float
    truth: dict[str, float]  # b1, b2, c1 per unit inertia
    noise_angle_rad: float


def make_prediction_set(
    prediction: IkedaPrediction,
    component: str,
    factor: float,
    seed: int | None = None,
    angles_deg: Sequence[float] = (10.0, 7.0, 4.0),
    duration_s: float = 40.0,
    rate_hz: float = 100.0,
) -> PredictionSet:
    """Decays at the prediction's speed and frequency whose damping is the prediction's own components,
    ``component`` times ``factor`` (the equivalent b1 + b2 model over the release angles), simulated by
    the independent reference integrator with MTi-class noise; the runs carry their speed as a recording
    does. A hidden-effect set for predictions: what is scaled is known."""
    rng = np.random.default_rng(seed)
    releases = [np.deg2rad(a + rng.uniform(-0.5, 0.5)) * rng.choice([-1.0, 1.0]) for a in angles_deg]
    amplitudes = [abs(float(a)) for a in releases]
    truth = prediction.equivalent_model(amplitudes)
    if component:
        term, share = prediction_shares(prediction, amplitudes)[component]
        truth[term] += (factor - 1.0) * share
    t = np.arange(round(duration_s * rate_hz)) / rate_hz
    speed = prediction.inputs.speed_m_s
    runs = []
    for i, angle0 in enumerate(releases):
        angle, rate = simulate_decay(truth, t, float(angle0))
        runs.append(
            DecayRun(
                t=t.copy(),
                angle=angle + rng.normal(0.0, NOISE_ANGLE_RAD, t.size),
                rate=rate + rng.normal(0.0, NOISE_RATE_RAD_S, t.size),
                name=f"prediction-{i + 1}",
                meta={"release_angle_deg": float(np.rad2deg(angle0)), "speed_m_s": speed},
            )
        )
    return PredictionSet(runs, component, factor, speed, truth, NOISE_ANGLE_RAD)
