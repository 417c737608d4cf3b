"""A decay as the guided session measures it, good on every check; a test changes only what it tests."""

from __future__ import annotations

from typing import Any

from tankdaq.records import DecayEnd
from tankdaq.session.checks import Measured


def measured_decay(**changes: Any) -> Measured:
    """Measured values that pass every check of a 10 deg condition, with ``changes`` on top."""
    base = dict(
        angle_deg=10.2,
        still_water_deg=0.1,
        ended=DecayEnd.SETTLED,
        half_cycles=14,
        r2_angle=0.997,
        coefficients={"b1": 0.02, "b2": 4.6},
        natural_period_s=1.66,
        b_eq_per_s=2.6,
        max_rate_deg_s=30.0,
        free_end="record",
    )
    return Measured(**{**base, **changes})
