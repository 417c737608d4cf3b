"""Kato's skin friction of a rolling hull (Kato 1958, as Ikeda's method and ITTC 7.5-02-07-04.5 §2.2.3 take
it), with Ikeda's forward-speed factor: one formula for the simplified Ikeda prediction (``physics.ikeda``,
laminar C_F as the authors' program) and the full-scale friction correction (``physics.friction_scaling``,
with Kato's turbulent term). Pure: numbers in, numbers out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Kato:
    """Kato's skin friction of a rolling hull (ITTC 7.5-02-07-04.5 §2.2.3), from the main particulars:
    the wetted surface S_f = Lpp (1.75 d + CB B) and mean radius r_f = d ((0.887 + 0.145 CB)(1.7 + CB B/d)
    - 2 OG/d) / π of the authors' program; OG downward positive. One formula for the simplified Ikeda
    prediction (laminar) and the friction correction of full-scale results (with the turbulent term)."""

    lpp_m: float
    beam_m: float
    draft_m: float
    block_coefficient: float
    og_m: float

    @property
    def radius_m(self) -> float:
        cb, d = self.block_coefficient, self.draft_m
        return d * ((0.887 + 0.145 * cb) * (1.7 + cb * self.beam_m / d) - 2.0 * self.og_m / d) / math.pi

    @property
    def surface_m2(self) -> float:
        return self.lpp_m * (1.75 * self.draft_m + self.block_coefficient * self.beam_m)

    def reynolds(self, omega_rad_s: float, amplitude_rad: float, nu_m2_s: float) -> float:
        """Kato's Reynolds number of the roll, 3.22 r_f² φa² / (T ν) = 0.512 (r_f φa)² ω / ν."""
        period = 2 * math.pi / omega_rad_s
        return 3.22 * self.radius_m**2 * amplitude_rad**2 / (period * nu_m2_s)

    def damping(
        self,
        omega_rad_s: float,
        amplitude_rad: float,
        nu_m2_s: float,
        rho_kg_m3: float,
        speed_m_s: float = 0.0,
        turbulent: bool = False,
    ) -> float:
        """B_F (N·m·s/rad) = 4/(3π) ρ S_f r_f³ φa ω C_f × (1 + 4.1 U/(ωL)) (Ikeda's speed factor), with
        C_f = 1.328 Re^-1/2, plus 0.014 Re^-0.114 with ``turbulent`` (Kato's turbulent term)."""
        reynolds = self.reynolds(omega_rad_s, amplitude_rad, nu_m2_s)
        cf = 1.328 * reynolds**-0.5 + (0.014 * reynolds**-0.114 if turbulent else 0.0)
        b_f = (4.0 / (3.0 * math.pi) * rho_kg_m3 * self.surface_m2 * self.radius_m**3 * amplitude_rad
               * omega_rad_s * cf)  # fmt: skip
        return b_f * friction_speed_factor(speed_m_s, omega_rad_s, self.lpp_m)


def friction_speed_factor(speed_m_s: float, omega_rad_s: float, lpp_m: float) -> float:
    """Ikeda's forward-speed factor of friction, 1 + 4.1 U/(ωL): the same at both scales by Froude."""
    return 1.0 + 4.1 * speed_m_s / (omega_rad_s * lpp_m)
