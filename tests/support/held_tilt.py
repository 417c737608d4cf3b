"""The simplest decay a lab records: a held tilt, then the release, as arrays and as a CSV file.

Shared by the tests that read decays (CSV import, identify, hulls, input checks, untrusted files).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tankdaq.physics.decay import simulate_decay

#: The decay's coefficients and its sample rate.
TRUTH = {"b1": 0.3, "b2": 0.4, "c1": 14.0}
RATE_HZ = 100.0


def held_tilt(
    angle0_deg: float = 8.0, hold_s: float = 2.0, free_s: float = 12.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A held tilt, then the released decay (s, rad, rad/s): exact, to test reading and not noise."""
    t = np.arange(int((hold_s + free_s) * RATE_HZ)) / RATE_HZ
    free = t >= hold_s
    angle, rate = np.full(t.size, math.radians(angle0_deg)), np.zeros(t.size)
    angle[free], rate[free] = simulate_decay(TRUTH, t[free] - hold_s, math.radians(angle0_deg))
    return t, angle, rate


def write_held_tilt_csv(
    path: Path,
    hold_s: float = 2.0,
    angle0_deg: float = 8.0,
    extra: bool = True,
    noise_deg: float = 0.0,
    seed: int = 0,
) -> Path:
    """The held tilt as a lab's CSV (time_s, angle_deg, rate_deg_s with white noise of ``noise_deg``;
    ``extra``: a heave and another angle beside them)."""
    t, angle, rate = held_tilt(angle0_deg, hold_s)
    rng = np.random.default_rng(seed)
    angle_deg = np.degrees(angle) + rng.normal(0, noise_deg, t.size)
    columns = {
        "time_s": t,
        "angle_deg": angle_deg,
        "rate_deg_s": np.degrees(rate) + rng.normal(0, noise_deg, t.size),
    }
    if extra:
        columns |= {"heave_m": 0.001 * np.sin(t), "other_angle_deg": 0.5 * np.ones(t.size)}
    path.write_text(
        ",".join(columns)
        + "\n"
        + "\n".join(",".join(f"{col[i]:.9g}" for col in columns.values()) for i in range(t.size))
    )
    return path
