"""Vehicles for the diving-plane model: constants, derivatives, and where each number comes from.

The model is seed 003's eq. 1 (surge, heave, pitch in the vertical plane, origin at the centre of
gravity), written with prime-system derivatives: a force term ``T`` enters as ``rho/2 L^n T' * (states)``.
Vehicle files may give derivatives as prime values or as dimensional SI values (as Prestero publishes
REMUS); both become prime values here so every vehicle is compared on the same footing.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..config.hulls import config_dir
from ..errors import ConfigError, InputError


@dataclass(frozen=True)
class Term:
    """One derivative of the model: its equation, its rho/2 L^n power and what it multiplies."""

    name: str
    equation: str  # "X", "Z" or "M"
    length_power: int
    multiplies: str
    inertia: bool = False


#: Every term of the model in its fixed order (docs/auv.md has the same table).
TERMS: tuple[Term, ...] = (
    Term("X_udot", "X", 3, "du/dt", inertia=True),
    Term("X_wq", "X", 3, "w q"),
    Term("X_u|u|", "X", 2, "u |u|"),
    Term("X_dsds", "X", 2, "u^2 delta_s^2"),
    Term("Z_qdot", "Z", 4, "dq/dt", inertia=True),
    Term("Z_wdot", "Z", 3, "dw/dt", inertia=True),
    Term("Z_uq", "Z", 3, "u q"),
    Term("Z_uu", "Z", 2, "u^2"),
    Term("Z_uw", "Z", 2, "u w"),
    Term("Z_w|w|", "Z", 2, "w |w|"),
    Term("Z_ds", "Z", 2, "u^2 delta_s"),
    Term("M_qdot", "M", 5, "dq/dt", inertia=True),
    Term("M_q|q|", "M", 5, "q |q|"),
    Term("M_wdot", "M", 4, "dw/dt", inertia=True),
    Term("M_uq", "M", 4, "u q"),
    Term("M_uu", "M", 3, "u^2"),
    Term("M_uw", "M", 3, "u w"),
    Term("M_w|w|", "M", 3, "w |w|"),
    Term("M_ds", "M", 3, "u^2 delta_s"),
)
TERM_BY_NAME: dict[str, Term] = {t.name: t for t in TERMS}
#: The derivatives identified from a manoeuvre (the added-mass ones are taken as known, as in the seed).
VISCOUS_TERMS: tuple[str, ...] = tuple(t.name for t in TERMS if not t.inertia)

_REQUIRED_CONSTANTS = (
    "length_m",
    "rho_kg_m3",
    "weight_n",
    "buoyancy_n",
    "bg_m",
    "iy_kg_m2",
    "nominal_speed_m_s",
)
GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class Vehicle:
    """A vehicle's constants and prime-system derivatives (absent terms are zero)."""

    name: str
    description: str
    length_m: float
    rho_kg_m3: float
    weight_n: float
    buoyancy_n: float
    bg_m: float
    iy_kg_m2: float
    nominal_speed_m_s: float
    thrust_n: float
    derivatives: dict[str, float]
    plane_time_constant_s: float = 0.1
    plane_limit_deg: float | None = None
    sources: dict[str, str] = field(default_factory=dict)
    path: Path | None = None

    @property
    def mass_kg(self) -> float:
        return self.weight_n / GRAVITY_M_S2

    def scale(self, length_power: int) -> float:
        """rho/2 L^n: turns a prime derivative into a dimensional one."""
        return 0.5 * self.rho_kg_m3 * self.length_m**length_power

    def coefficient(self, name: str) -> float:
        return self.derivatives.get(name, 0.0)

    def present_terms(self, names: tuple[str, ...] = VISCOUS_TERMS) -> tuple[str, ...]:
        """The terms of ``names`` this vehicle's model has (non-zero standard value)."""
        return tuple(n for n in names if self.coefficient(n) != 0.0)

    def with_derivatives(self, derivatives: dict[str, float], name: str | None = None) -> Vehicle:
        """The same vehicle with some derivatives replaced (for perturbation and identified models)."""
        merged = {**self.derivatives, **derivatives}
        return replace(self, derivatives=merged, name=name or self.name)

    def to_dict(self) -> dict[str, object]:
        """Plain-data form (the MCAP attachment and --json output)."""
        return {
            "name": self.name,
            "description": self.description,
            "system": "prime",
            "constants": {
                "length_m": self.length_m,
                "rho_kg_m3": self.rho_kg_m3,
                "weight_n": self.weight_n,
                "buoyancy_n": self.buoyancy_n,
                "bg_m": self.bg_m,
                "iy_kg_m2": self.iy_kg_m2,
                "nominal_speed_m_s": self.nominal_speed_m_s,
                "thrust_n": self.thrust_n,
                "plane_time_constant_s": self.plane_time_constant_s,
                **({"plane_limit_deg": self.plane_limit_deg} if self.plane_limit_deg is not None else {}),
            },
            "derivatives": dict(self.derivatives),
            "sources": dict(self.sources),
        }


def list_vehicles() -> list[str]:
    """Names of the vehicles in configs/vehicles."""
    return sorted(p.stem for p in (config_dir() / "vehicles").glob("*.toml"))


def load_vehicle(name: str) -> Vehicle:
    """Load ``configs/vehicles/<name>.toml``; an unknown name lists the known ones."""
    path = config_dir() / "vehicles" / f"{name}.toml"
    if not path.is_file():
        raise InputError(f"unknown vehicle {name!r}; known vehicles: {', '.join(list_vehicles()) or 'none'}")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a BOM from Notepad is dropped
    except (tomllib.TOMLDecodeError, OSError) as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    vehicle = vehicle_from_dict(data, default_name=name)
    return replace(vehicle, path=path)


def vehicle_from_dict(data: dict, default_name: str = "vehicle") -> Vehicle:
    """Build a Vehicle from the TOML/JSON layout; dimensional derivatives become prime values."""
    constants = data.get("constants", {})
    missing = [k for k in _REQUIRED_CONSTANTS if k not in constants]
    if missing:
        raise ConfigError(f"vehicle {default_name!r}: missing constants {missing}")
    raw = data.get("derivatives", {})
    unknown = sorted(set(raw) - set(TERM_BY_NAME))
    if unknown:
        raise ConfigError(
            f"vehicle {default_name!r}: unknown derivatives {unknown}; known: {', '.join(TERM_BY_NAME)}"
        )
    system = data.get("system", "prime")
    if system not in ("prime", "dimensional"):
        raise ConfigError(
            f"vehicle {default_name!r}: system must be 'prime' or 'dimensional', not {system!r}"
        )
    length_m = float(constants["length_m"])
    rho = float(constants["rho_kg_m3"])
    derivatives = {}
    for key, value in raw.items():
        divisor = 0.5 * rho * length_m ** TERM_BY_NAME[key].length_power if system == "dimensional" else 1.0
        derivatives[key] = float(value) / divisor
    limit = constants.get("plane_limit_deg")
    speed = float(constants["nominal_speed_m_s"])
    # Constant propeller thrust X_T: given, or self-propulsion at the nominal speed (balances the u|u| drag).
    drag_at_speed = -0.5 * rho * length_m**2 * derivatives.get("X_u|u|", 0.0) * speed**2
    thrust = float(constants.get("thrust_n", drag_at_speed))
    return Vehicle(
        name=data.get("name", default_name),
        description=data.get("description", ""),
        length_m=length_m,
        rho_kg_m3=rho,
        weight_n=float(constants["weight_n"]),
        buoyancy_n=float(constants["buoyancy_n"]),
        bg_m=float(constants["bg_m"]),
        iy_kg_m2=float(constants["iy_kg_m2"]),
        nominal_speed_m_s=speed,
        thrust_n=thrust,
        plane_time_constant_s=float(constants.get("plane_time_constant_s", 0.1)),
        plane_limit_deg=None if limit is None else float(limit),
        derivatives=derivatives,
        sources=dict(data.get("sources", {})),
    )
