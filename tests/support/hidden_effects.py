"""One draw of the discrepancy workflow on decays with a hidden effect, and what makes a draw right:
shared by ``test_diagnose_workflow`` (a few draws of each effect) and ``bench/bench_hidden_effects.py``
(the full count, 20 of each)."""

from __future__ import annotations

from typing import Any

import numpy as np

from tankdaq.diagnose.effects import EFFECTS
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.diagnose.workflow import Diagnoser

#: The share of draws in which the hidden effect must be named first (and nothing added when none is).
NAMED_SHARE = 0.9
#: The fitted parameter that measures each hidden effect (the truth uses the same names).
MEASURED_BY = {
    "damping.quadratic": "b2",
    "damping.cubic": "b3",
    "restoring.cubic": "c3",
    "restoring.sine": "s1",
    "sensor.offset": "angle_offset_rad",
    "restoring.asymmetric": "c2",
    "sensor.gyro_bias": "gyro_bias_rad_s",
    "sensor.lag": "angle_lag_s",
    "sensor.gain": "angle_gain_error",
    "friction.coulomb": "fc",
    "coupling.heave": "k_heave_m",
    "coupling.other_rotation": "k_other_angle",
    "coupling.unmeasured": "ring_omega_rad_s",  # heave not recorded: its frequency is what can be measured
}


def final_value(diagnoser: Diagnoser, name: str) -> float | None:
    final = diagnoser.final_
    if name == "angle_offset_rad":
        return float(np.mean(final.offsets)) if final.offsets else None
    return final.coefficients.get(name)


def diagnose_draw(effects: tuple[str, ...], seed: int) -> dict[str, Any]:
    """One draw, reduced to what the criteria need (runs in a worker process)."""
    data = make_decay_set(effects, seed=seed)
    diagnoser = Diagnoser().fit(data.runs)
    values = {e: final_value(diagnoser, MEASURED_BY[e]) for e in effects if e in MEASURED_BY}
    return {
        "families": [s.effect.family for s in diagnoser.steps_],
        "rms_over_noise": diagnoser.final_.rms_angle / data.noise_angle_rad,
        "gap_all_outputs": 1 - diagnoser.final_.rms_noise_units / diagnoser.baseline_.rms_noise_units,
        "relative_error": {
            e: None if v is None else abs(v / data.truth[MEASURED_BY[e]] - 1) for e, v in values.items()
        },
        "cut_s": [c for s in diagnoser.steps_ for c in s.cut_s],
        "onset_s": data.onset_s,
    }


def named_first(key: str, outcome: dict[str, Any]) -> bool:
    """Whether the draw named the hidden effect's family first (for no effect: added nothing)."""
    return not outcome["families"] if not key else outcome["families"][:1] == [EFFECTS[key].family]


def draw_faults(key: str, outcome: dict[str, Any]) -> list[str]:
    """What is wrong with one draw whatever was named: the final fit meets the noise, the gap over all
    outputs (in noise units: a gyro bias lives in the rate) at least halves, the effect's size is within
    20 %, and nothing of a late burst is kept."""
    faults = []
    if outcome["rms_over_noise"] > 1.3:
        faults.append(f"final RMS {outcome['rms_over_noise']:.2f} x noise")
    if key and outcome["gap_all_outputs"] < 0.5:
        faults.append(f"gap shrank {outcome['gap_all_outputs']:.0%}")
    error = outcome["relative_error"].get(key) if key in MEASURED_BY else 0.0
    if error is None or error > 0.2:
        faults.append(f"{MEASURED_BY[key]} error {error}")
    if key == "disturbance.late" and max(outcome["cut_s"]) > outcome["onset_s"] + 0.5:
        faults.append("the late burst is kept")
    return faults


#: The prediction sets: the KVLCC2 model's simplified Ikeda prediction at the 15.5 kn carriage speed
#: (0.967 m/s at model scale), one component scaled by a factor drawn from a band on either side of 1.
PREDICTION_HULL, PREDICTION_SPEED_M_S = "kvlcc2", 0.967
PREDICTION_CASES: tuple[tuple[str, tuple[float, float]], ...] = (
    ("", (1.0, 1.0)),
    ("B_L", (1.5, 2.0)),
    ("B_L", (0.4, 0.65)),
    ("B_W", (0.3, 0.6)),
    ("B_F", (2.0, 3.0)),
    ("B_E", (2.5, 4.0)),
)


def prediction_draw(component: str, band: tuple[float, float], seed: int) -> dict[str, Any]:
    """One draw of a prediction set (decays from the prediction's components, one scaled) compared with
    the prediction at the decays' speed, reduced to what the criteria need."""
    from tankdaq.config.hulls import ikeda_prediction, load_hull
    from tankdaq.diagnose.compare import SimulationComparison
    from tankdaq.diagnose.simulation import SimulationRequest, resolve_simulation
    from tankdaq.diagnose.synthetic import make_prediction_set
    from tankdaq.physics.ikeda import COMPONENTS

    hull = load_hull(PREDICTION_HULL)
    factor = float(np.random.default_rng(seed).uniform(*band))
    data = make_prediction_set(ikeda_prediction(hull, 1.0, PREDICTION_SPEED_M_S), component, factor, seed)
    simulation = resolve_simulation(["ikeda"], SimulationRequest(tuple(data.runs), "roll", hull, 1.0))
    comparison = SimulationComparison(simulation, max_steps=3, hull=hull).fit(data.runs)
    name = COMPONENTS[component][1] if component else ""
    scaled = [s for s in comparison.scalings_ if name in s.members]
    return {
        "factor": factor,
        "speed_m_s": simulation.speed_m_s,
        "lift_predicted": "B_L" in (simulation.shares or {}),
        "effects": [s.effect.key for s in comparison.steps_],
        "scaled_terms": [s.term for s in comparison.scalings_],
        "named": bool(scaled) and comparison.steps_[0].effect.increments == scaled[0].term,
        "factor_alone": scaled[0].alone()[name] if scaled else None,
        "gap_reduction": comparison.gap_reduction_,
        "verdict": comparison.verdict_,
    }


def prediction_faults(component: str, outcome: dict[str, Any]) -> list[str]:
    """What is wrong with one draw: the prediction is made at the decays' speed (lift in it), no rig
    friction is named, the scaled component is named first (its part of the model; for the control,
    nothing), the gap shrinks by >= 70 % and the component's own factor is within 20 % of the truth."""
    faults = []
    if not outcome["lift_predicted"] or outcome["speed_m_s"] != PREDICTION_SPEED_M_S:
        faults.append(f"predicted at {outcome['speed_m_s']} m/s without lift")
    if "friction.coulomb" in outcome["effects"]:
        faults.append("rig friction named")
    if not component:
        return faults + ([f"named {outcome['effects']}"] if outcome["effects"] else [])
    if not outcome["named"]:
        faults.append(f"named {outcome['effects']} ({outcome['scaled_terms']})")
    if outcome["gap_reduction"] < 0.7:
        faults.append(f"gap shrank {outcome['gap_reduction']:.0%}")
    alone = outcome["factor_alone"]
    if alone is None or abs(alone / outcome["factor"] - 1) > 0.2:
        faults.append(f"factor {alone} against {outcome['factor']:.3g}")
    return faults
