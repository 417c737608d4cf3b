"""A hull's optional ``[particulars]``: the main particulars the simplified Ikeda prediction
(``tankdaq predict``) and full-scale results need (docs/hulls.md).

Parsed and checked where the hull file is read (``config.load_hull``): known keys only, finite
numbers, positive where physical, KG or OG but not both. ``config.ikeda_prediction`` joins them
with the hull's GM and gyradius, and ``plausible`` checks them against each other and physics
before any formula runs: a unit slip (a length in mm, a density in t/m^3, a viscosity in cSt) or a
typo is refused in one line that names the input, a displacement that disagrees with rho Lpp B d CB
is warned.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import ConfigError, InputError
from ..physics.friction_scaling import (
    DEFAULT_TEMPERATURE_C,
    FrictionScaling,
    Water,
    WaterKind,
    checked_temperature_c,
)
from ..physics.ikeda import IkedaInputs, IkedaOutOfRange, Kato
from ..physics.scaling import FroudeScale

#: The optional ``[particulars]`` keys (docs/hulls.md): main particulars for ``tankdaq predict``'s
#: simplified Ikeda prediction and for full-scale results. Key -> what it is.
PARTICULAR_KEYS = {
    "lpp_m": "length between perpendiculars Lpp (m)",
    "beam_m": "moulded beam B (m)",
    "draft_m": "draft d at the design draft T (m)",
    "block_coefficient": "block coefficient CB = volume / (Lpp B d)",
    "midship_coefficient": "midship section coefficient CMID = A_mid / (B d)",
    "kg_m": "centre of gravity above the keel KG (m)",
    "og_m": "still water level to the roll axis OG (m), downward positive (instead of kg_m)",
    "bilge_keel_length_m": "bilge keel length lBK (m), 0 for none",
    "bilge_keel_breadth_m": "bilge keel breadth (height) bBK (m), 0 for none",
    "speed_m_s": "carriage speed of the decay tests (m/s), predict's default --speed",
    "scale_factor": "scale factor lambda = ship length / model length (for --full-scale)",
    "added_inertia_fraction": "added roll inertia over the dry inertia (for the natural frequency)",
    "water_density_kg_m3": "tank water density (kg/m^3), default 1000",
    "kinematic_viscosity_m2_s": "kinematic viscosity (m^2/s), default 1.14e-6",
    "water_temperature_c": "tank water temperature of the decays (degC), for --full-scale's friction",
    "sea_temperature_c": "the ship's sea water temperature (degC), default 15, for --full-scale's friction",
    "sea_kinematic_viscosity_m2_s": "the ship's sea water viscosity (m^2/s), instead of sea_temperature_c",
}
#: Keys that may be zero or negative (the rest must be positive).
_SIGNED = {"og_m"}
_NON_NEGATIVE = {"bilge_keel_length_m", "bilge_keel_breadth_m", "speed_m_s", "added_inertia_fraction"}
#: Water temperatures, checked against the range ITTC's water properties are used at.
_TEMPERATURES = {"water_temperature_c", "sea_temperature_c"}
#: What a prediction cannot do without.
IKEDA_KEYS = ("lpp_m", "beam_m", "draft_m", "block_coefficient", "midship_coefficient")


@dataclass(frozen=True)
class MainParticulars:
    """The ``[particulars]`` of a hull at the design draft, with per-draft overrides
    (``[particulars.drafts."0.9T"]``)."""

    values: dict[str, float]
    drafts: dict[float, dict[str, float]] = field(default_factory=dict)

    def at(self, draft: float) -> dict[str, float]:
        """The particulars at a draft factor: the design values, with that draft's overrides."""
        for factor, overrides in self.drafts.items():
            if abs(factor - draft) < 1e-9:
                return {**self.values, **overrides}
        return dict(self.values)


def parse_particulars(table: Any, path: Path, parse_draft: Callable[[str], float]) -> MainParticulars:
    """``[particulars]``: known keys only, finite numbers, positive where physical; kg_m or og_m.
    ``parse_draft`` reads the drafts of ``[particulars.drafts."0.9T"]`` (config's grammar)."""
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [particulars] must be a table of key = number")
    drafts = table.get("drafts", {})
    if not isinstance(drafts, dict):
        raise ConfigError(f'{path}: [particulars.drafts] must hold tables like [particulars.drafts."0.9T"]')
    values = _particular_values({k: v for k, v in table.items() if k != "drafts"}, path, "particulars")
    by_draft = {
        parse_draft(text): _particular_values(spec, path, f'particulars.drafts."{text}"')
        for text, spec in drafts.items()
    }
    return MainParticulars(values, by_draft)


def _particular_values(table: Any, path: Path, where: str) -> dict[str, float]:
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [{where}] must be a table of key = number")
    unknown = sorted(set(table) - set(PARTICULAR_KEYS))
    if unknown:
        raise ConfigError(
            f"{path}: unknown key(s) {unknown} in [{where}]; known: {', '.join(PARTICULAR_KEYS)}"
        )
    if "kg_m" in table and "og_m" in table:
        raise ConfigError(f"{path}: [{where}] gives both kg_m and og_m; give one (OG = d - KG)")
    values = {}
    for key, value in table.items():
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ConfigError(f"{path}: [{where}] {key} = {value!r} must be a finite number")
        if key in _TEMPERATURES or key == "sea_kinematic_viscosity_m2_s":
            try:
                if key in _TEMPERATURES:
                    checked_temperature_c(value, f"{path}: [{where}] {key}")
                else:
                    _refuse_outside(value, SEA_VISCOSITY, key, f"{path} [{where}]")
            except InputError as exc:
                raise ConfigError(str(exc)) from None
        elif (key in _NON_NEGATIVE and value < 0) or (key not in _SIGNED | _NON_NEGATIVE and value <= 0):
            sign = "zero or more" if key in _NON_NEGATIVE else "positive"
            raise ConfigError(f"{path}: [{where}] {key} = {value!r} must be {sign} ({PARTICULAR_KEYS[key]})")
        values[key] = float(value)
    return values


def ikeda_inputs(p: dict[str, float], speed_m_s: float) -> IkedaInputs:
    """The formulas' inputs from a hull's particulars (OG = d - KG unless og_m is given)."""
    if not (math.isfinite(speed_m_s) and 0 <= speed_m_s <= MAX_SPEED_M_S):
        raise InputError(
            f"speed {speed_m_s:g} m/s: give a carriage speed of 0 to {MAX_SPEED_M_S:g} m/s "
            "(not knots or km/h)"
        )
    return IkedaInputs(
        lpp_m=p["lpp_m"],
        beam_m=p["beam_m"],
        draft_m=p["draft_m"],
        block_coefficient=p["block_coefficient"],
        midship_coefficient=p["midship_coefficient"],
        og_m=p["og_m"] if "og_m" in p else p["draft_m"] - p["kg_m"],
        bilge_keel_length_m=p.get("bilge_keel_length_m", 0.0),
        bilge_keel_breadth_m=p.get("bilge_keel_breadth_m", 0.0),
        speed_m_s=speed_m_s,
        kinematic_viscosity_m2_s=p.get("kinematic_viscosity_m2_s", 1.14e-6),
        rho_kg_m3=p.get("water_density_kg_m3", 1000.0),
    )


#: A towing carriage's speed at most (m/s); beyond it a speed is in knots or km/h, or a typo.
MAX_SPEED_M_S = 20.0


@dataclass(frozen=True)
class Sane:
    """The range a real hull in a model basin keeps a number in, and the unit slips that leave it: a
    value times ``factor`` back inside the range names ``unit`` as the likely slip."""

    low: float
    high: float
    what: str
    slips: tuple[tuple[float, str], ...] = ()


#: Water of a model basin, fresh to salt, at about 0-30 degC (ITTC's reporting lists both).
WATER_DENSITY = Sane(990.0, 1030.0, "fresh to salt water, kg/m^3", ((1e3, "t/m^3 or g/cm^3"),))
KINEMATIC_VISCOSITY = Sane(
    0.8e-6, 1.8e-6, "water at 0-30 degC, m^2/s", ((1e-6, "mm^2/s (cSt)"), (1e-4, "cm^2/s (St)"))
)
#: Proportions of a hull (monohull to catamaran and SWATH, whose beam is the overall one).
LENGTH_BEAM = Sane(1.0, 30.0, "Lpp/B of a hull", ((1e-3, "lpp_m in mm"), (1e3, "beam_m in mm")))
BEAM_DRAFT = Sane(0.5, 30.0, "B/d of a hull", ((1e-3, "beam_m in mm"), (1e3, "draft_m in mm")))
KG_DRAFT = Sane(0.05, 10.0, "KG/d: G above the keel, within ten drafts", ((1e-3, "kg_m in mm"),))
GM_BEAM = Sane(1e-4, 2.0, "GM/B", ((1e-3, "gm_m in mm"),))
GYRADIUS_BEAM = Sane(
    0.1, 2.0, "roll gyradius k/B (ITTC: 0.35-0.40 B)", ((1e-3, "radius_of_gyration_m in mm"),)
)
ADDED_INERTIA = Sane(0.0, 2.0, "added over dry roll inertia, typically 0.05-0.4", ((1e-2, "a percentage"),))
#: The displacement against rho Lpp B d CB: warned beyond 10 %, refused beyond a factor 1.5.
DISPLACEMENT_WARN, DISPLACEMENT_REFUSE = 0.10, 1.5


def _refuse_outside(value: float, sane: Sane, said: str, where: object) -> None:
    """One line naming the input, its range and the likely unit slip when ``value`` is outside."""
    if sane.low <= value <= sane.high:
        return
    slip = next((unit for factor, unit in sane.slips if sane.low <= value * factor <= sane.high), None)
    hint = f"{slip}?" if slip else "a typo or a unit slip?"
    raise InputError(
        f"{said} = {value:.4g} is outside {sane.low:g}..{sane.high:g} ({sane.what}): {hint} fix it in {where}"
    )


def plausible(p: dict[str, float], design: dict[str, float], hull: Any) -> list[IkedaOutOfRange]:
    """``p`` (a hull's particulars at a draft; ``design`` at T) against physics and each other, before
    any formula runs: refused in one line when a number cannot be a model basin's, the displacement
    warned when it disagrees with rho Lpp B d CB. ``hull``: its file, ``displacement_kg`` and roll GM
    and gyradius (``config.Hull``)."""
    where = hull.path or hull.name
    checks: list[tuple[float, Sane, str]] = [
        (p.get("water_density_kg_m3", 1000.0), WATER_DENSITY, "water_density_kg_m3"),
        (p.get("kinematic_viscosity_m2_s", 1.14e-6), KINEMATIC_VISCOSITY, "kinematic_viscosity_m2_s"),
        (p["lpp_m"] / p["beam_m"], LENGTH_BEAM, f"lpp_m / beam_m ({p['lpp_m']:g} / {p['beam_m']:g})"),
        (p["beam_m"] / p["draft_m"], BEAM_DRAFT, f"beam_m / draft_m ({p['beam_m']:g} / {p['draft_m']:g})"),
    ]
    kg = p["kg_m"] if "kg_m" in p else p["draft_m"] - p["og_m"]
    checks.append(
        (kg / p["draft_m"], KG_DRAFT, f"KG / draft_m ({'kg_m' if 'kg_m' in p else 'from og_m'} {kg:g})")
    )
    if "added_inertia_fraction" in p:
        checks.append((p["added_inertia_fraction"], ADDED_INERTIA, "added_inertia_fraction"))
    roll = hull.particulars("roll")
    if roll.gm_m is not None:
        checks.append((roll.gm_m / p["beam_m"], GM_BEAM, f"gm_m / beam_m ({roll.gm_m:g} / {p['beam_m']:g})"))
    if roll.radius_of_gyration_m is not None:
        k = roll.radius_of_gyration_m
        checks.append(
            (k / p["beam_m"], GYRADIUS_BEAM, f"radius_of_gyration_m / beam_m ({k:g} / {p['beam_m']:g})")
        )
    for value, sane, said in checks:
        _refuse_outside(value, sane, said, where)
    return _displacement(design, hull.displacement_kg, where)


def _displacement(p: dict[str, float], displacement_kg: float | None, where: object) -> list[IkedaOutOfRange]:
    """The hull's displacement against rho Lpp B d CB at its design draft (the formulas' volume)."""
    needed = ("lpp_m", "beam_m", "draft_m", "block_coefficient")
    if displacement_kg is None or any(key not in p for key in needed):
        return []
    formed = p.get("water_density_kg_m3", 1000.0) * math.prod(p[key] for key in needed)
    ratio = displacement_kg / formed
    said = (
        f"displacement_kg {displacement_kg:.4g} kg is {ratio:.3g} times rho Lpp B d CB = {formed:.4g} kg "
        "(the formulas' volume)"
    )
    if not 1 / DISPLACEMENT_REFUSE <= ratio <= DISPLACEMENT_REFUSE:
        slip = next((unit for unit, factor in (("g", 1e3), ("t", 1e-3)) if 0.5 < ratio / factor < 2.0), "")
        hint = f"the displacement in {slip}?" if slip else "a typo or a unit slip?"
        raise InputError(f"{said}: {hint} fix displacement_kg or the particulars in {where}")
    if abs(ratio - 1.0) > DISPLACEMENT_WARN:
        line = (
            f"{said}: more than {DISPLACEMENT_WARN:.0%} apart; check both (the inertia uses the displacement)"
        )
        return [IkedaOutOfRange("displacement", ratio, 1 - DISPLACEMENT_WARN, 1 + DISPLACEMENT_WARN, line)]
    return []


#: What the full-scale friction correction needs of ``[particulars]`` (with kg_m or og_m).
FRICTION_KEYS = ("lpp_m", "beam_m", "draft_m", "block_coefficient")
#: The ship's sea water at 0-30 degC (ITTC 7.5-02-01-03: 1.83e-6 at 0 degC).
SEA_VISCOSITY = Sane(0.8e-6, 1.9e-6, "sea water at 0-30 degC, m^2/s", KINEMATIC_VISCOSITY.slips)


@dataclass(frozen=True)
class WaterSettings:
    """The water temperatures given for the friction correction (``--water-temperature``,
    ``--sea-temperature``; degC), None where the hull's keys or ITTC's 15 degC decide."""

    water_temperature_c: float | None = None
    sea_temperature_c: float | None = None

    def __post_init__(self) -> None:
        for name, value in (("--water-temperature", self.water_temperature_c),
                            ("--sea-temperature", self.sea_temperature_c)):  # fmt: skip
            if value is not None:
                checked_temperature_c(value, name)


def friction_scaling(
    hull: Any,
    draft: float,
    scale: FroudeScale,
    speed_m_s: float | None,
    settings: WaterSettings,
    speed_from: str = "the recordings' speed_m_s",
) -> FrictionScaling | str:
    """The friction correction of a hull at a draft factor (``physics.friction_scaling``), or the one line
    that says which ``[particulars]`` key to add. ``speed_m_s``: the decays' carriage speed where the
    recordings say it, else the hull's ``speed_m_s``, else 0. Given viscosities are checked against water."""
    where = f"[particulars] of {hull.path or hull.name}"
    p = hull.main_particulars.at(draft)
    missing = [k for k in FRICTION_KEYS if k not in p] + ([] if {"kg_m", "og_m"} & set(p) else ["kg_m"])
    if missing:
        return f"no friction correction: add {', '.join(missing)} to {where} (Froude only)"
    if abs(draft - 1.0) > 1e-9 and not any(abs(f - draft) < 1e-9 for f in hull.main_particulars.drafts):
        return f'no friction correction at this draft: add [particulars.drafts."{draft:g}T"] to {where}'
    og = p["og_m"] if "og_m" in p else p["draft_m"] - p["kg_m"]
    kato = Kato(p["lpp_m"], p["beam_m"], p["draft_m"], p["block_coefficient"], og)
    if speed_m_s is not None:
        speed = speed_m_s
    elif "speed_m_s" in p:
        speed, speed_from = p["speed_m_s"], f"speed_m_s in {where}"
    else:
        speed, speed_from = 0.0, f"assumed: the recordings and {where} give no speed_m_s"
    model = _water(p, WaterKind.FRESH, settings.water_temperature_c, where)
    ship = _water(p, WaterKind.SEA, settings.sea_temperature_c, where)
    rho = p.get("water_density_kg_m3", 1000.0)
    return FrictionScaling(scale, kato, speed, model, ship, rho, speed_from)


def _water(p: dict[str, float], kind: WaterKind, option_c: float | None, where: str) -> Water:
    """One side's water: the option's temperature, else the hull's viscosity, else its temperature, else
    ITTC's 15 degC (said so)."""
    fresh = kind is WaterKind.FRESH
    option, viscosity_key = ("--water-temperature", "kinematic_viscosity_m2_s") if fresh else (
        "--sea-temperature", "sea_kinematic_viscosity_m2_s")  # fmt: skip
    temperature_key = "water_temperature_c" if fresh else "sea_temperature_c"
    if option_c is not None:
        return Water.at(kind, option_c, option)
    if viscosity_key in p:
        sane = KINEMATIC_VISCOSITY if fresh else SEA_VISCOSITY
        _refuse_outside(p[viscosity_key], sane, viscosity_key, where)
        return Water(kind, p[viscosity_key], None, f"{viscosity_key} in {where}")
    if temperature_key in p:
        return Water.at(kind, p[temperature_key], f"{temperature_key} in {where}")
    return Water.at(kind, DEFAULT_TEMPERATURE_C, f"assumed: set {temperature_key} or {option}")
