"""Known-truth decays for the identification tests (imported by the other test_ident_* files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

#: Where the shared real data lives (outside the repository, read in place).
DATA_DIR = Path(__file__).resolve().parents[3] / "shared" / "data"
KVLCC2_21338 = DATA_DIR / "kvlcc2-roll-decay" / "model_test_21338.csv"

#: A roll decay with every canonical effect present and clearly above the noise.
TRUTH_ALL = {
    "b1": 0.3,
    "b2": 0.4,
    "b3": 0.5,
    "c1": 14.0,
    "c2": 0.8,
    "c3": 60.0,
    "s1": 14.0,
    "s2": 0.8,
    "s3": 60.0,
}

ANGLE_NOISE = 1e-3  # rad
RATE_NOISE = 5e-3  # rad/s


def synthetic_run(
    coefficients: dict[str, float],
    seed: int,
    angle0: float = 0.3,
    duration_s: float = 15.0,
    rate_hz: float = 100.0,
    offset: float = 0.01,
    with_rate: bool = True,
    name: str = "synthetic",
) -> DecayRun:
    """A simulated decay (reference integrator) with white noise on angle and gyro and an angle offset."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration_s * rate_hz)) / rate_hz
    angle, rate = simulate_decay(coefficients, t, angle0, 0.0)
    return DecayRun(
        t=t,
        angle=angle + offset + rng.normal(0.0, ANGLE_NOISE, t.size),
        rate=rate + rng.normal(0.0, RATE_NOISE, t.size) if with_rate else None,
        name=name,
    )


def truth_for(terms: tuple[str, ...]) -> dict[str, float]:
    """The known coefficients restricted to a model's terms."""
    return {k: TRUTH_ALL[k] for k in terms}
