"""Simulated campaigns with known truth for the uncertainty budget's coverage (tests/ident/test_budget.py with
a few, bench/bench_budget_coverage.py with 200): does U (k = 2) of the natural period and of B_eq/I at 5 deg
cover the truth?

A campaign is three repeat decays of one condition (the catamaran's roll at T from 10 deg, give or take
0.3 deg) measured by one device: white angle and rate noise as ``SimulatedTest`` (about the MTi-G's),
the angle quantised to 0.01 deg and offset by a bias, and the device's errors the budget's Type B
assumes, drawn once per campaign: an angle scale error of the profile's accuracy over the initial angle,
and a clock error of its ppm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tankdaq.campaign.synthetic import SimulatedTest, simulated_decay
from tankdaq.config.hulls import load_hull
from tankdaq.ident.budget_fit import fit_budgets
from tankdaq.ident.budget_inputs import MTI_G_710
from tankdaq.ident.derived import b_eq, natural_period, tested_amplitudes_deg
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.records import DecayRun

INITIAL_DEG = 10.0
REPEATS = 3
TEST = SimulatedTest(duration_s=8.0, hold_s=0.2, rate_hz=100.0)
QUANTUM_RAD = math.radians(0.01)
#: The two quantities the issue's coverage is about, by their budget keys.
KEYS = ("natural_period_s", "b_eq_per_s@5")


@dataclass(frozen=True)
class Outcome:
    """One campaign: per key, the error of the reported value from the truth, and its u_c and U."""

    error: dict[str, float]
    combined: dict[str, float]
    expanded: dict[str, float]

    def covered(self, key: str) -> bool:
        return abs(self.error[key]) <= self.expanded[key]


def truth() -> dict[str, float]:
    return load_hull("catamaran").simulation_model("roll").coefficients(1.0)


def campaign(seed: int, coefficients: dict[str, float], device_error: bool = True) -> Outcome:
    """One simulated campaign fitted and budgeted as ``identify`` does; without ``device_error`` the
    device's scale and clock are exact (the budget's Type B then covers an error that is not there)."""
    rng = np.random.default_rng([seed, 38])
    profile = MTI_G_710
    errors = rng.standard_normal(2) if device_error else np.zeros(2)
    gain = 1.0 + errors[0] * profile.angle_accuracy_deg / INITIAL_DEG
    clock = 1.0 + errors[1] * profile.clock_ppm * 1e-6
    bias = math.radians(0.2) * rng.standard_normal()
    runs = []
    for i in range(REPEATS):
        t, angle, rate = simulated_decay(coefficients, INITIAL_DEG + 0.3 * rng.standard_normal(), TEST, rng)
        k = TEST.release_index
        measured = np.round((gain * angle[k:] + bias) / QUANTUM_RAD) * QUANTUM_RAD
        runs.append(
            DecayRun(
                t=clock * (t[k:] - t[k]),
                angle=measured,
                rate=gain * rate[k:] / clock,
                axis="roll",
                name=f"run{i}",
            )
        )
    fit = OutputErrorFit(sorted(coefficients)).fit(runs)
    found = {
        b.key: b for b in fit_budgets(fit, runs, tested_amplitudes_deg(runs, fit.offsets_), device=profile)
    }
    true = {
        "natural_period_s": natural_period(coefficients),
        "b_eq_per_s@5": b_eq(coefficients, math.radians(5)),
    }
    return Outcome(
        {k: found[k].value - true[k] for k in KEYS},
        {k: found[k].combined for k in KEYS},
        {k: found[k].expanded for k in KEYS},
    )


def coverage(outcomes: list[Outcome]) -> dict[str, dict[str, float]]:
    """Per key: the share of campaigns whose U covers the truth, and the RMS of error / u_c."""
    return {
        key: {
            "covered": float(np.mean([o.covered(key) for o in outcomes])),
            "rms_error_over_u": float(
                np.sqrt(np.mean([(o.error[key] / o.combined[key]) ** 2 for o in outcomes]))
            ),
        }
        for key in KEYS
    }
