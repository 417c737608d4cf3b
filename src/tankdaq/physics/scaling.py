"""Froude scaling between model and ship (scale factor λ = ship length / model length).

Time and periods × √λ, angles unchanged, lengths × λ, mass × λ³, inertia × λ⁵, B44 (N·m·s) × λ^4.5,
non-dimensional B̂44 unchanged (lab-practice §1). A decay coefficient per unit inertia scales with the
power of time in its unit (``physics.terms.TERM_TABLE``): b1 (1/s) × λ^-1/2, b2 (1/rad) unchanged,
c1 (1/s²) × 1/λ. Friction is a Reynolds effect and does not follow Froude's law: FRICTION_NOTE says so
wherever a result is shown at full scale, and ``physics.friction_scaling`` makes the ITTC correction.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass

from ..errors import InputError
from .terms import TERM_TABLE

FRICTION_NOTE = (
    "Froude's law scales skin friction too, which is a Reynolds effect: by Froude alone the model's friction "
    "share is too large at full scale; the friction-corrected B44 moves Kato's friction component from the "
    "model's to the ship's Reynolds number (ITTC 7.5-02-07-04.5)"
)


def time_power(term: str) -> int:
    """The power of seconds in a term's coefficient unit: ``1/s`` -> -1, ``s/rad^2`` -> 1."""
    numerator, _, denominator = TERM_TABLE[term].unit.partition("/")

    def seconds(part: str) -> int:
        return sum(int(p or 1) for p in re.findall(r"\bs(?:\^(\d))?\b", part))

    return seconds(numerator) - seconds(denominator)


@dataclass(frozen=True)
class FroudeScale:
    """Model -> ship at scale λ; ``inverse`` goes back."""

    scale: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise InputError(
                f"scale factor {self.scale} must be a positive number (ship length / model length)"
            )

    @property
    def inverse(self) -> FroudeScale:
        return FroudeScale(1.0 / self.scale)

    def time_s(self, value: float) -> float:
        """Times and periods × √λ."""
        return value * math.sqrt(self.scale)

    def length_m(self, value: float) -> float:
        return value * self.scale

    def mass_kg(self, value: float) -> float:
        return value * self.scale**3

    def inertia_kg_m2(self, value: float) -> float:
        return value * self.scale**5

    def damping_n_m_s(self, value: float) -> float:
        """Dimensional roll damping B44 (N·m·s/rad) × λ^4.5."""
        return value * self.scale**4.5

    def speed_m_s(self, value: float) -> float:
        return value * math.sqrt(self.scale)

    def coefficients(self, coefficients: Mapping[str, float]) -> dict[str, float]:
        """Decay coefficients per unit inertia at the other scale (each × λ^(p/2), p its power of s)."""
        return {k: v * self.scale ** (time_power(k) / 2) for k, v in coefficients.items()}
