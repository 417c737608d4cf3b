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
