"""A hull's optional ``[particulars]``: the main particulars the simplified Ikeda prediction
(``tankdaq predict``) and full-scale results need (docs/hulls.md).

Parsed and checked where the hull file is read (``config.load_hull``): known keys only, finite
numbers, positive where physical, KG or OG but not both. ``config.ikeda_prediction`` joins them
with the hull's GM and gyradius.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import ConfigError, InputError
from .physics.ikeda import IkedaInputs

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
}
#: Keys that may be zero or negative (the rest must be positive).
_SIGNED = {"og_m"}
_NON_NEGATIVE = {"bilge_keel_length_m", "bilge_keel_breadth_m", "speed_m_s", "added_inertia_fraction"}
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
        if (key in _NON_NEGATIVE and value < 0) or (key not in _SIGNED | _NON_NEGATIVE and value <= 0):
            sign = "zero or more" if key in _NON_NEGATIVE else "positive"
            raise ConfigError(f"{path}: [{where}] {key} = {value!r} must be {sign} ({PARTICULAR_KEYS[key]})")
        values[key] = float(value)
    return values


def ikeda_inputs(p: dict[str, float], speed_m_s: float) -> IkedaInputs:
    """The formulas' inputs from a hull's particulars (OG = d - KG unless og_m is given)."""
    if not (math.isfinite(speed_m_s) and speed_m_s >= 0):
        raise InputError(f"speed {speed_m_s} m/s must be zero or more")
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
