"""Full scale the ITTC way: Froude scaling with the friction component moved to the ship's Reynolds number.

Skin friction is a Reynolds effect and does not follow Froude's law. ITTC 7.5-02-07-04.5 computes the
friction component B_F (Kato's formula, ``physics.ikeda.Kato``, with Ikeda's forward-speed factor
1 + 4.1 U/(ωL)) at the model's and at the ship's Reynolds number and corrects the extrapolation by the
difference: B44_ship = λ^4.5 B44_model - λ^4.5 B_F(model) + B_F(ship). Eddy, bilge keel and wave parts
are taken to scale by Froude (lab-practice §6). Kato's C_F keeps its turbulent term here (0.014 Re^-0.114):
at a ship's Reynolds number (10^6..10^8) it is most of the friction.

The water (ITTC 7.5-02-01-03, "Fresh Water and Seawater Properties", 2011): kinematic viscosity ν = μ/ρ with
μ of pure water by Sharqawy, Lienhard and Zubair (2010) eq. 23 (a fit of IAPWS 2008), of sea water at the
standard absolute salinity 35.16504 g/kg by their eq. 22, and ρ by the UNESCO one-atmosphere equation of
state (Millero and Poisson 1981) at practical salinity 0 and 35: ITTC's tables computed their sea water
this way, and these formulas give them within 0.03 % over 1-30 °C (tests/physics/test_friction_scaling.py).
A temperature of 0-40 °C goes in; a lab may give ν itself instead (``Water`` says which it was).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from enum import Enum
from typing import Any

from ..errors import InputError
from .kato import Kato
from .scaling import FroudeScale

#: ITTC 7.5-02-01-03's sea water: absolute salinity 35.16504 g/kg (practical salinity 35).
SEA_SALINITY_KG_KG = 0.03516504
SEA_PRACTICAL_SALINITY = 35.0
#: The temperatures the formulas are used at (ITTC's tables; model basins and the sea), °C.
MIN_TEMPERATURE_C, MAX_TEMPERATURE_C = 0.0, 40.0
#: The assumed temperatures when nobody says (ITTC's standard for extrapolation, 15 °C, for both).
DEFAULT_TEMPERATURE_C = 15.0
SOURCE = "ITTC 7.5-02-01-03 (2011) fresh/sea water: mu by Sharqawy et al. 2010 eq. 22-23, rho by UNESCO 1981"


class WaterKind(Enum):
    """Which water: the tank's fresh water or the ship's sea water."""

    FRESH = "fresh"
    SEA = "sea"


def checked_temperature_c(value: float, said: str) -> float:
    """A water temperature the formulas hold at (0-40 °C), else one line naming where it came from."""
    if not (math.isfinite(value) and MIN_TEMPERATURE_C <= value <= MAX_TEMPERATURE_C):
        raise InputError(
            f"{said} {value:g}: give a water temperature of {MIN_TEMPERATURE_C:g} to {MAX_TEMPERATURE_C:g} "
            "degC (not kelvin or fahrenheit)"
        )
    return float(value)


def _pure_water_viscosity_pa_s(t: float) -> float:
    """Dynamic viscosity of pure water at 0.1 MPa (Sharqawy et al. 2010 eq. 23, IAPWS 2008 within 0.05 %)."""
    return 4.2844e-5 + 1.0 / (0.157 * (t + 64.993) ** 2 - 91.296)


def _density_kg_m3(t: float, salinity: float) -> float:
    """UNESCO one-atmosphere equation of state (Millero and Poisson 1981), practical salinity ``salinity``."""
    pure = (999.842594 + 6.793952e-2 * t - 9.09529e-3 * t**2 + 1.001685e-4 * t**3 - 1.120083e-6 * t**4
            + 6.536332e-9 * t**5)  # fmt: skip
    a = 8.24493e-1 - 4.0899e-3 * t + 7.6438e-5 * t**2 - 8.2467e-7 * t**3 + 5.3875e-9 * t**4
    b = -5.72466e-3 + 1.0227e-4 * t - 1.6546e-6 * t**2
    return pure + a * salinity + b * salinity**1.5 + 4.8314e-4 * salinity**2


def fresh_water_viscosity(temperature_c: float) -> float:
    """Kinematic viscosity of fresh water (m²/s) at a temperature (°C), as ITTC 7.5-02-01-03 tables it."""
    t = checked_temperature_c(temperature_c, "fresh water temperature")
    return _pure_water_viscosity_pa_s(t) / _density_kg_m3(t, 0.0)


def sea_water_viscosity(temperature_c: float) -> float:
    """Kinematic viscosity of sea water (m²/s, salinity 35.16504 g/kg) at a temperature (°C), as ITTC
    7.5-02-01-03 tables it."""
    t = checked_temperature_c(temperature_c, "sea water temperature")
    s = SEA_SALINITY_KG_KG
    a = 1.541 + 1.998e-2 * t - 9.52e-5 * t**2
    b = 7.974 - 7.561e-2 * t + 4.724e-4 * t**2
    mu = _pure_water_viscosity_pa_s(t) * (1.0 + a * s + b * s * s)
    return mu / _density_kg_m3(t, SEA_PRACTICAL_SALINITY)


@dataclass(frozen=True)
class Water:
    """The water on one side of the extrapolation: its kind, its kinematic viscosity and where that came
    from (a temperature through ITTC's properties, or a value given as such)."""

    kind: WaterKind
    viscosity_m2_s: float
    temperature_c: float | None = None  # None: the viscosity was given, not looked up
    given_as: str = ""  # the key or option that gave it

    @classmethod
    def at(cls, kind: WaterKind, temperature_c: float, given_as: str) -> Water:
        viscosity = fresh_water_viscosity if kind is WaterKind.FRESH else sea_water_viscosity
        checked = checked_temperature_c(temperature_c, given_as)
        return cls(kind, viscosity(checked), checked, given_as)

    @property
    def line(self) -> str:
        """What was assumed, in words: ``fresh water 15 degC (default): nu 1.1388e-06 m^2/s (ITTC ...)``."""
        if self.temperature_c is None:
            return f"{self.kind.value} water: nu {self.viscosity_m2_s:.5g} m^2/s (given: {self.given_as})"
        return (
            f"{self.kind.value} water {self.temperature_c:g} degC ({self.given_as}): "
            f"nu {self.viscosity_m2_s:.5g} m^2/s"
        )


@dataclass(frozen=True)
class FullScaleB44:
    """B44 at full scale at one amplitude, both ways, and the friction that makes the difference (N·m·s/rad;
    ``share`` = correction / Froude B44)."""

    amplitude_deg: float
    froude_n_m_s: float
    corrected_n_m_s: float
    correction_n_m_s: float
    share: float
    friction_model_n_m_s: float
    friction_model_froude_n_m_s: float
    friction_ship_n_m_s: float
    reynolds_model: float
    reynolds_ship: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class FrictionScaling:
    """Model -> ship with the friction correction. ``kato`` and ``speed_m_s`` are the model's (its
    particulars and carriage speed), ``model_water`` and ``ship_water`` the two sides' viscosities;
    ``rho_kg_m3`` is the tank water's density, used at both sides as Froude's λ^4.5 does (so the
    correction is the Reynolds effect alone). ``inverse`` goes back, the correction undone."""

    scale: FroudeScale
    kato: Kato
    speed_m_s: float
    model_water: Water
    ship_water: Water
    rho_kg_m3: float
    speed_from: str = ""  # where the speed came from (the recordings, the hull, assumed)

    @property
    def ship_kato(self) -> Kato:
        """The hull at the other scale: every length × λ."""
        length = self.scale.length_m
        k = self.kato
        return replace(k, lpp_m=length(k.lpp_m), beam_m=length(k.beam_m), draft_m=length(k.draft_m),
                       og_m=length(k.og_m))  # fmt: skip

    @property
    def inverse(self) -> FrictionScaling:
        return FrictionScaling(
            self.scale.inverse, self.ship_kato, self.scale.speed_m_s(self.speed_m_s), self.ship_water,
            self.model_water, self.rho_kg_m3, self.speed_from,
        )  # fmt: skip

    def at(self, b44_n_m_s: float, omega_rad_s: float, amplitude_rad: float) -> FullScaleB44:
        """The model's B44 (N·m·s/rad) at roll frequency ω and amplitude φa, at full scale both ways."""
        if not (math.isfinite(omega_rad_s) and omega_rad_s > 0 and math.isfinite(amplitude_rad)):
            raise InputError(f"full scale needs a positive roll frequency, not {omega_rad_s:g} rad/s")
        amplitude = abs(amplitude_rad)
        if amplitude == 0:
            raise InputError("the friction correction needs a roll amplitude above zero")
        ship_omega = omega_rad_s / math.sqrt(self.scale.scale)
        ship_speed = self.scale.speed_m_s(self.speed_m_s)
        model = self.kato.damping(omega_rad_s, amplitude, self.model_water.viscosity_m2_s, self.rho_kg_m3,
                                  self.speed_m_s, turbulent=True)  # fmt: skip
        ship = self.ship_kato.damping(ship_omega, amplitude, self.ship_water.viscosity_m2_s, self.rho_kg_m3,
                                      ship_speed, turbulent=True)  # fmt: skip
        froude = self.scale.damping_n_m_s(b44_n_m_s)
        model_froude = self.scale.damping_n_m_s(model)
        correction = ship - model_froude
        return FullScaleB44(
            amplitude_deg=math.degrees(amplitude),
            froude_n_m_s=froude,
            corrected_n_m_s=froude + correction,
            correction_n_m_s=correction,
            share=correction / froude if froude != 0 else math.nan,
            friction_model_n_m_s=model,
            friction_model_froude_n_m_s=model_froude,
            friction_ship_n_m_s=ship,
            reynolds_model=self.kato.reynolds(omega_rad_s, amplitude, self.model_water.viscosity_m2_s),
            reynolds_ship=self.ship_kato.reynolds(ship_omega, amplitude, self.ship_water.viscosity_m2_s),
        )

    def assumptions(self) -> dict[str, Any]:
        """What the correction assumed, for ``--json`` and the text (one line each in ``lines``)."""
        return {
            "method": "ITTC 7.5-02-07-04.5: B_F (Kato, C_F = 1.328 Re^-0.5 + 0.014 Re^-0.114, "
            "x (1 + 4.1 U/(wL))) at model and ship Reynolds number; "
            "B44_ship = Froude B44 - Froude B_F(model) + B_F(ship)",
            "scale_factor": self.scale.scale,
            "model_water": self.model_water.line,
            "ship_water": self.ship_water.line,
            "model_viscosity_m2_s": self.model_water.viscosity_m2_s,
            "ship_viscosity_m2_s": self.ship_water.viscosity_m2_s,
            "model_temperature_c": self.model_water.temperature_c,
            "ship_temperature_c": self.ship_water.temperature_c,
            "density_kg_m3": self.rho_kg_m3,
            "water_properties": SOURCE,
            "model_speed_m_s": self.speed_m_s,
            "speed_from": self.speed_from,
            "ship_speed_m_s": self.scale.speed_m_s(self.speed_m_s),
            "wetted_surface_m2": self.kato.surface_m2,
            "roll_radius_m": self.kato.radius_m,
        }


def assumption_lines(assumptions: dict[str, Any]) -> list[str]:
    """``FrictionScaling.assumptions`` as the text reports print it."""
    return [
        f"  friction correction: {assumptions['method']}",
        f"  model: {assumptions['model_water']}; speed {assumptions['model_speed_m_s']:g} m/s "
        f"({assumptions['speed_from']}); "
        f"S_f {assumptions['wetted_surface_m2']:.4g} m^2, r_f {assumptions['roll_radius_m']:.4g} m",
        f"  ship: {assumptions['ship_water']}; speed {assumptions['ship_speed_m_s']:.4g} m/s; "
        f"density {assumptions['density_kg_m3']:g} kg/m^3 at both scales (Froude's lambda^4.5)",
        f"  water properties: {assumptions['water_properties']}",
    ]


def correct_prediction(summary: dict[str, Any], friction: FrictionScaling | str) -> None:
    """Adds the friction-corrected B44 to each amplitude of a prediction's ``full_scale`` part
    (``physics.ikeda.IkedaPrediction.summary``), or the line that says why it could not be made."""
    ship = summary["full_scale"]
    if isinstance(friction, str):
        ship["friction_missing"] = friction
        return
    ship["friction"] = friction.assumptions()
    for row, model in zip(ship["amplitudes"], summary["amplitudes"], strict=True):
        found = friction.at(model["b44_n_m_s"], summary["omega_rad_s"], math.radians(model["amplitude_deg"]))
        row |= {
            "b44_corrected_n_m_s": found.corrected_n_m_s,
            "friction_correction_n_m_s": found.correction_n_m_s,
            "friction_share": found.share,
            "reynolds_model": found.reynolds_model,
            "reynolds_ship": found.reynolds_ship,
        }


def amplitude_lines(ship: dict[str, Any]) -> list[str]:
    """A prediction's full-scale B44 per amplitude, Froude and, where made, friction-corrected."""
    lines = []
    for r in ship["amplitudes"]:
        line = f"  {r['amplitude_deg']:>6.2f} deg  B44 {r['b44_n_m_s']:.4g} N·m·s/rad (Froude)"
        if "b44_corrected_n_m_s" in r:
            line += (
                f", friction-corrected {r['b44_corrected_n_m_s']:.4g} (correction "
                f"{r['friction_correction_n_m_s']:+.4g}, {r['friction_share']:+.1%}; Reynolds "
                f"{r['reynolds_model']:.3g} model, {r['reynolds_ship']:.3g} ship)"
            )
        lines.append(line)
    if "friction" in ship:
        lines += assumption_lines(ship["friction"])
    elif "friction_missing" in ship:
        lines.append(f"  {ship['friction_missing']}")
    return lines
