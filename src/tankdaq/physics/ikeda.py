"""Roll damping predicted from the hull's main particulars: the simplified Ikeda method.

Kawahara, Maekawa and Ikeda (2009), "A simple prediction formula of roll damping of conventional cargo
ships on the basis of Ikeda's method and its limitation", J. Shipping and Ocean Engineering: regression
formulas of Ikeda's components for friction (Kato), wave, eddy and bilge keel at zero speed, from Lpp, B,
d, CB, CMID, OG, the bilge keel, the roll amplitude and frequency. With speed, Ikeda's hull lift and the
forward-speed factors of friction and eddy (Ikeda, Himeno and Tanaka 1978, as ITTC 7.5-02-07-04.5 §2.2
gives them) are applied; the wave component keeps its zero-speed value (its speed factor is not applied,
and a finding says so). The coefficients are the authors' Fortran program's (Roll_Damping.for,
2009-07-08), read through its public Python conversion (rolldecay-estimators, ``simplified_ikeda.py``).

Every result is non-dimensional, B̂ = B44 / (ρ ∇ B²) · √(B / 2g) with ∇ = Lpp B d CB, and an
equivalent linear damping at the amplitude asked (B44 in N·m·s/rad). Pure: numbers in, numbers out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from .friction_scaling import amplitude_lines
from .kato import Kato
from .scaling import FRICTION_NOTE, FroudeScale

#: The components, in the order they are shown: key -> (symbol, what it is, linear or quadratic).
COMPONENTS: dict[str, tuple[str, str, str]] = {
    "B_F": ("B̂F", "friction", "linear"),
    "B_W": ("B̂W", "wave", "linear"),
    "B_E": ("B̂E", "eddy", "quadratic"),
    "B_L": ("B̂L", "lift", "linear"),
    "B_BK": ("B̂BK", "bilge keel", "quadratic"),
}
TOTAL = "B_44"
LINEAR_PART = tuple(k for k, v in COMPONENTS.items() if v[2] == "linear")
QUADRATIC_PART = tuple(k for k, v in COMPONENTS.items() if v[2] == "quadratic")

#: The validity limits printed in the paper (and checked by the authors' program).
LIMITS: dict[str, tuple[float, float, str]] = {
    "CB": (0.5, 0.85, "block coefficient CB"),
    "B/d": (2.5, 4.5, "beam over draft B/d"),
    "OG/d": (-1.5, 0.2, "OG/d (roll axis below the still water level, downward positive)"),
    "CMID": (0.9, 0.99, "midship coefficient CMID"),
    "bBK/B": (0.01, 0.06, "bilge keel breadth over beam bBK/B"),
    "lBK/Lpp": (0.05, 0.4, "bilge keel length over Lpp lBK/Lpp"),
    "omega_hat": (0.0, 1.0, "non-dimensional frequency ω̂ = ω √(B/2g)"),
}

#: 8 / (3 pi): the describing function of |x'|x' (ITTC eq. 15).
QUADRATIC_EQUIVALENT = 8.0 / (3.0 * math.pi)


def hat_factor(beam_m: float, displaced_mass_kg: float, g_m_s2: float = 9.81) -> float:
    """B̂44 per B44 (per N·m·s/rad): √(B/2g) / (ρ ∇ B²), ρ∇ the displaced mass (lab-practice §1)."""
    return math.sqrt(beam_m / (2 * g_m_s2)) / (displaced_mass_kg * beam_m**2)


@dataclass(frozen=True)
class IkedaInputs:
    """What the formulas need, SI. ``og_m``: still water level O to roll axis G, downward positive
    (the paper's sign: G below the waterline gives OG > 0); ``from_kg`` builds it from KG."""

    lpp_m: float
    beam_m: float
    draft_m: float
    block_coefficient: float
    midship_coefficient: float
    og_m: float
    bilge_keel_length_m: float = 0.0
    bilge_keel_breadth_m: float = 0.0
    speed_m_s: float = 0.0
    kinematic_viscosity_m2_s: float = 1.14e-6
    rho_kg_m3: float = 1000.0
    g_m_s2: float = 9.81

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not math.isfinite(value):
                raise InputError(f"Ikeda input {name} = {value} is not a finite number")
            if value <= 0 and name not in (
                "og_m",
                "bilge_keel_length_m",
                "bilge_keel_breadth_m",
                "speed_m_s",
            ):
                raise InputError(f"Ikeda input {name} = {value:g} must be positive")
            if value < 0 and name != "og_m":
                raise InputError(f"Ikeda input {name} = {value:g} must not be negative")
        if (self.bilge_keel_length_m > 0) != (self.bilge_keel_breadth_m > 0):
            raise InputError("a bilge keel needs both its length and its breadth (or neither)")

    @classmethod
    def from_kg(cls, kg_m: float, **inputs: float) -> IkedaInputs:
        """Inputs with OG = d - KG (G below the still water level is positive)."""
        return cls(og_m=inputs["draft_m"] - kg_m, **inputs)

    @property
    def volume_m3(self) -> float:
        """The formulas' displacement volume, Lpp B d CB."""
        return self.lpp_m * self.beam_m * self.draft_m * self.block_coefficient

    @property
    def hat_factor(self) -> float:
        """B̂ per B44 (per N·m·s): √(B/2g) / (ρ ∇ B²)."""
        return hat_factor(self.beam_m, self.rho_kg_m3 * self.volume_m3, self.g_m_s2)

    def omega_hat(self, omega_rad_s: float) -> float:
        return omega_rad_s * math.sqrt(self.beam_m / (2 * self.g_m_s2))

    @property
    def kato(self) -> Kato:
        """The hull's skin friction (Kato) from these particulars."""
        return Kato(self.lpp_m, self.beam_m, self.draft_m, self.block_coefficient, self.og_m)


@dataclass(frozen=True)
class IkedaOutOfRange:
    """One input outside the range the formulas were fitted on (or a part not applied)."""

    name: str
    value: float
    low: float
    high: float
    line: str


#: A ratio made of two lengths may miss a limit it equals by a rounding (OG = -1.5 d gives OG/d =
#: -1.5000000000000002): within this it is on the limit, not beyond it.
RATIO_ROUNDING = 1e-9


def validity(inputs: IkedaInputs, omega_rad_s: float) -> list[IkedaOutOfRange]:
    """Every input outside the paper's limits, named, one line each; plus the speed caveat."""
    values = {
        "CB": inputs.block_coefficient,
        "B/d": inputs.beam_m / inputs.draft_m,
        "OG/d": inputs.og_m / inputs.draft_m,
        "CMID": inputs.midship_coefficient,
        "omega_hat": inputs.omega_hat(omega_rad_s),
    }
    if inputs.bilge_keel_length_m > 0:
        values["bBK/B"] = inputs.bilge_keel_breadth_m / inputs.beam_m
        values["lBK/Lpp"] = inputs.bilge_keel_length_m / inputs.lpp_m
    findings = []
    for name, value in values.items():
        low, high, what = LIMITS[name]
        if not low - RATIO_ROUNDING <= value <= high + RATIO_ROUNDING:
            side = "below" if value < low else "above"
            findings.append(
                IkedaOutOfRange(
                    name,
                    value,
                    low,
                    high,
                    f"{what} = {value:.4g} is {side} the paper's range {low:g}..{high:g}",
                )
            )
    if inputs.speed_m_s > 0:
        findings.append(
            IkedaOutOfRange(
                "speed",
                inputs.speed_m_s,
                0.0,
                0.0,
                f"speed {inputs.speed_m_s:g} m/s: the simplified formulas are for zero speed; lift and the "
                "speed factors of friction and eddy are Ikeda's, the wave component is its zero-speed value",
            )
        )
    return findings


def components(inputs: IkedaInputs, omega_rad_s: float, amplitude_rad: float) -> dict[str, float]:
    """B̂F, B̂W, B̂E, B̂L, B̂BK and their total B̂44 at roll frequency ω (rad/s) and amplitude φa (rad)."""
    if not (math.isfinite(omega_rad_s) and omega_rad_s > 0):
        raise InputError(f"roll frequency {omega_rad_s} rad/s must be positive")
    if not (math.isfinite(amplitude_rad) and amplitude_rad > 0):
        raise InputError(f"roll amplitude {amplitude_rad} rad must be positive")
    try:
        out = _components(inputs, omega_rad_s, amplitude_rad)
    except (OverflowError, ZeroDivisionError, ValueError):
        out = {TOTAL: math.inf}
    if not all(math.isfinite(value) for value in out.values()):
        raise InputError(
            f"the simplified Ikeda formulas give no finite damping at {math.degrees(amplitude_rad):.4g} deg "
            f"and {omega_rad_s:.4g} rad/s for these inputs ({_described(inputs)}): check their units"
        )
    return out


def _described(inputs: IkedaInputs) -> str:
    return ", ".join(f"{name} {value:.4g}" for name, value in vars(inputs).items() if name != "g_m_s2")


def _components(inputs: IkedaInputs, omega_rad_s: float, amplitude_rad: float) -> dict[str, float]:
    bd = inputs.beam_m / inputs.draft_m
    ogd = inputs.og_m / inputs.draft_m
    omega_hat = inputs.omega_hat(omega_rad_s)
    phi_deg = math.degrees(amplitude_rad)
    out = {
        "B_F": _friction(inputs, omega_rad_s, amplitude_rad),
        "B_W": _wave(bd, inputs.block_coefficient, inputs.midship_coefficient, ogd, omega_hat),
        "B_E": _eddy(bd, inputs.block_coefficient, inputs.midship_coefficient, ogd, omega_hat, amplitude_rad),
        "B_L": _lift(inputs) * inputs.hat_factor,
        "B_BK": _bilge_keel(inputs, bd, ogd, omega_hat, phi_deg),
    }
    if inputs.speed_m_s > 0:
        reduced = omega_rad_s * inputs.lpp_m / inputs.speed_m_s  # K = ωL/U
        out["B_E"] *= (0.04 * reduced) ** 2 / (1.0 + (0.04 * reduced) ** 2)
    out[TOTAL] = sum(out[k] for k in COMPONENTS)
    return out


def _friction(inputs: IkedaInputs, omega: float, phi: float) -> float:
    """Kato's skin friction as the simplified method takes it (laminar C_F, speed factor), B̂F."""
    return inputs.kato.damping(omega, phi, inputs.kinematic_viscosity_m2_s, inputs.rho_kg_m3,
                               inputs.speed_m_s) * inputs.hat_factor  # fmt: skip


def _poly(x: float, *coefficients: float) -> float:
    """c0 x^n + c1 x^(n-1) + ... + cn (highest power first, as the paper writes them)."""
    return float(np.polyval(coefficients, x))


def _wave(bd: float, cb: float, cm: float, ogd: float, omega_hat: float) -> float:
    """The wave component's regression in B/d, CB, CMID, OG/d and ω̂ (zero speed)."""
    x4 = 1.0 - ogd
    a11 = _poly(cb, _poly(bd, -0.002222, 0.040871, -0.286866, 0.599424),
                _poly(bd, 0.010185, -0.161176, 0.904989, -1.641389),
                _poly(bd, -0.015422, 0.220371, -1.084987, 1.834167))  # fmt: skip
    a12 = _poly(cb, _poly(bd, -0.0628667, 0.4989259, 0.52735, -10.7918672, 16.616327),
                _poly(bd, 0.1140667, -0.8108963, -2.2186833, 25.1269741, -37.7729778),
                _poly(bd, -0.0589333, 0.2639704, 3.1949667, -21.8126569, 31.4113508),
                _poly(bd, 0.0107667, 0.0018704, -1.2494083, 6.9427931, -10.2018992))  # fmt: skip
    a13 = _poly(cb, _poly(bd, 0.192207, -2.787462, 12.507855, -14.764856),
                _poly(bd, -0.350563, 5.222348, -23.974852, 29.007851),
                _poly(bd, 0.237096, -3.535062, 16.368376, -20.539908),
                _poly(bd, -0.067119, 0.966362, -4.407535, 5.894703))  # fmt: skip
    aa11 = _poly(cb, _poly(bd, 17.945, -166.294, 489.799, -493.142),
                 _poly(bd, -25.507, 236.275, -698.683, 701.494),
                 _poly(bd, 9.077, -84.332, 249.983, -250.787))  # fmt: skip
    aa12 = _poly(cb, _poly(bd, -16.872, 156.399, -460.689, 463.848),
                 _poly(bd, 24.015, -222.507, 658.027, -660.665),
                 _poly(bd, -8.56, 79.549, -235.827, 236.579))  # fmt: skip
    a1 = (a11 * x4**2 + a12 * x4 + a13) * ((aa11 * cm + aa12) * (1 - x4) + 1.0)
    a2 = _poly(x4, -1.402, 7.189, -10.993, 9.45)
    a3 = _poly(x4, *(_poly(cb, *row) for row in _A3_ROWS)) + _aa3(bd, cb, x4)
    return a1 / omega_hat * math.exp(-a2 * (math.log(omega_hat) - a3) ** 2 / 1.44)


#: A31 ... A37 of the wave component: sixth-order polynomials in CB (highest power first).
_A3_ROWS = (
    (-7686.0287, 30131.5678, -49048.9664, 42480.7709, -20665.147, 5355.2035, -577.8827),
    (61639.9103, -241201.0598, 392579.5937, -340629.4699, 166348.6917, -43358.7938, 4714.7918),
    (-130677.4903, 507996.2604, -826728.7127, 722677.104, -358360.7392, 95501.4948, -10682.8619),
    (-110034.6584, 446051.22, -724186.4643, 599411.9264, -264294.7189, 58039.7328, -4774.6414),
    (709672.0656, -2803850.2395, 4553780.5017, -3888378.9905, 1839829.259, -457313.6939, 46600.823),
    (-822735.9289, 3238899.7308, -5256636.5472, 4500543.147, -2143487.3508, 538548.1194, -55751.1528),
    (299122.8727, -1175773.1606, 1907356.1357, -1634256.8172, 780020.9393, -196679.7143, 20467.0904),
)


def _aa3(bd: float, cb: float, x4: float) -> float:
    aa311 = _poly(cb, -17.102, 41.495, -33.234, 8.8007) * x4 + _poly(cb, 36.566, -89.203, 71.8, -18.108)
    aa31 = _poly(bd, -0.3767, 3.39, -10.356, 11.588) * aa311
    xx4 = x4 - _poly(bd, -0.0727, 0.7, -1.2818)
    shape = _poly(
        xx4, -1.05584, 12.688, -63.70534, 172.84571, -274.05701, 257.68705, -141.40915, 44.13177, -7.1654, 0.0
    )
    return aa31 * (shape + _poly(bd, -0.0495, 0.4518, -0.61655))


def _eddy(bd: float, cb: float, cm: float, ogd: float, omega_hat: float, phi: float) -> float:
    """The eddy component: proportional to ω̂ φa, so a quadratic damping."""
    ae = (-0.0182 * cb + 0.0155) * (bd - 1.8) ** 3 + _poly(cb, -79.414, 215.695, -215.883, 93.894, -14.848)
    be1 = (
        (3.98 * cb - 5.1525)
        * (-0.2 * bd + 1.6)
        * ogd
        * ((0.9717 * cb**2 - 1.55 * cb + 0.723) * ogd + 0.04567 * cb + 0.9408)
    )
    be2 = (0.25 * ogd + 0.95) * ogd + _poly(cb, -219.2, 443.7, -283.3, 59.6)
    be3 = -15 * cb * bd + 46.5 * cb + 11.2 * bd - 28.6
    cr = ae * math.exp(be1 + be2 * cm**be3)
    return 4.0 * omega_hat * phi / (3.0 * math.pi * cb * bd**3) * cr


def _bilge_keel(inputs: IkedaInputs, bd: float, ogd: float, omega_hat: float, phi_deg: float) -> float:
    """The bilge keel component (the formulas take φa in degrees); zero without a bilge keel."""
    if inputs.bilge_keel_length_m <= 0:
        return 0.0
    cb, cm = inputs.block_coefficient, inputs.midship_coefficient
    bbkb = inputs.bilge_keel_breadth_m / inputs.beam_m
    lbkl = inputs.bilge_keel_length_m / inputs.lpp_m
    fbk1 = (-0.3651 * cb + 0.3907) * (bd - 2.83) ** 2 - 2.21 * cb + 2.632
    fbk2 = 0.00255 * phi_deg**2 + 0.122 * phi_deg + 0.4794
    fbk3 = (-0.8913 * bbkb**2 - 0.0733 * bbkb) * lbkl**2 + (
        5.2857 * bbkb**2 - 0.01185 * bbkb + 0.00189
    ) * lbkl
    bbk1 = (5.0 * bbkb + 0.3 * bd - 0.2 * lbkl + 0.00125 * phi_deg**2 - 0.0425 * phi_deg - 1.86) * ogd
    bbk2 = -15.0 * bbkb + 1.2 * cb - 0.1 * bd - 0.0657 * ogd**2 + 0.0586 * ogd + 1.6164
    bbk3 = 2.5 * ogd + 15.75
    return fbk1 * fbk2 * fbk3 * math.exp(bbk1 + bbk2 * cm**bbk3) * omega_hat


def _lift(inputs: IkedaInputs) -> float:
    """Ikeda's hull lift damping B_L (N·m·s), proportional to speed; κ by CMID (ITTC §2.2.2)."""
    if inputs.speed_m_s <= 0:
        return 0.0
    d, og, cm = inputs.draft_m, inputs.og_m, inputs.midship_coefficient
    kappa = 0.0 if cm <= 0.92 else 0.1 if cm <= 0.97 else 0.3
    k_n = 2 * math.pi * d / inputs.lpp_m + kappa * (4.1 * inputs.beam_m / inputs.lpp_m - 0.045)
    l_o, l_r = 0.3 * d, 0.5 * d
    return (
        inputs.rho_kg_m3 / 2 * inputs.speed_m_s * inputs.lpp_m * d * k_n * l_o * l_r
        * (1 - 1.4 * og / l_r + 0.7 * og**2 / (l_o * l_r))
    )  # fmt: skip


def linear_quadratic_fit(
    omega_rad_s: float, amplitudes_rad: Sequence[float] | np.ndarray, b_eq: Sequence[float] | np.ndarray
) -> tuple[float, float]:
    """(b1, b2) of B_eq(φa)/I = b1 + 8/(3π) ω φa b2, least squares over two or more amplitudes
    (``ident.derived.b_eq``'s convention): a prediction's or a measurement's damping in one form."""
    amplitudes = np.asarray(amplitudes_rad, dtype=float)
    design = np.column_stack([np.ones(amplitudes.size), QUADRATIC_EQUIVALENT * omega_rad_s * amplitudes])
    (b1, b2), *_ = np.linalg.lstsq(design, np.asarray(b_eq, dtype=float), rcond=None)
    return float(b1), float(b2)


def fit_parts(
    omega_rad_s: float,
    amplitudes_rad: Sequence[float],
    parts: Sequence[Mapping[str, float]],
    keys: Sequence[str],
) -> tuple[float, float]:
    """(b1, b2) of B_eq(φa)/I = b1 + 8/(3π) ω φa b2 fitted to the sum of the components ``keys`` (per unit
    inertia, ``parts[i]`` at ``amplitudes_rad[i]``, distinct); one amplitude: the linear components give
    b1, the quadratic ones b2."""
    if not len(amplitudes_rad):
        raise InputError("give at least one roll amplitude for the equivalent model")
    slope = [QUADRATIC_EQUIVALENT * omega_rad_s * a for a in amplitudes_rad]
    if len(amplitudes_rad) == 1:
        b1 = sum(parts[0][k] for k in keys if k in LINEAR_PART)
        return b1, sum(parts[0][k] for k in keys if k in QUADRATIC_PART) / slope[0]
    return linear_quadratic_fit(omega_rad_s, amplitudes_rad, [sum(row[k] for k in keys) for row in parts])


def change_lines(
    omega_rad_s: float,
    amplitudes_rad: Sequence[float],
    parts: Sequence[Mapping[str, float]],
    measured_b1: float,
    measured_b2: float,
) -> list[str]:
    """Which components (per unit inertia at each amplitude, as ``fit_parts``) would have to change, by how
    much, to meet a measured b1, b2: the linear part (friction, wave, lift) carries b1, the quadratic part
    (eddy, bilge keel) b2."""
    lines = []
    for name, measured, keys, index, unit in (
        ("b1", measured_b1, LINEAR_PART, 0, "1/s"),
        ("b2", measured_b2, QUADRATIC_PART, 1, "1/rad"),
    ):
        predicted = fit_parts(omega_rad_s, amplitudes_rad, parts, keys)[index]
        other = fit_parts(omega_rad_s, amplitudes_rad, parts, [k for k in COMPONENTS if k not in keys])[index]
        need = measured - other  # what this part would have to give
        labels = ", ".join(f"{COMPONENTS[k][1]} {COMPONENTS[k][0]}" for k in keys)
        factor = f"x{need / predicted:.3g}" if predicted > 0 else "from zero (the prediction has none)"
        lines.append(
            f"{name}: predicted {predicted + other:.4g} {unit}, measured {measured:.4g} {unit}: "
            f"{labels} would have to change {factor} ({predicted:.4g} -> {need:.4g} {unit})"
        )
    return lines


@dataclass(frozen=True)
class IkedaPrediction:
    """The prediction at one roll frequency, ready to compare with a fit: components at any amplitude,
    the equivalent ``b1 + b2`` model per unit total inertia (SI, rad) and what would have to change."""

    inputs: IkedaInputs
    omega_rad_s: float
    total_inertia_kg_m2: float
    findings: list[IkedaOutOfRange] = field(default_factory=list)

    @classmethod
    def at(cls, inputs: IkedaInputs, omega_rad_s: float, total_inertia_kg_m2: float) -> IkedaPrediction:
        if not (math.isfinite(total_inertia_kg_m2) and total_inertia_kg_m2 > 0):
            raise InputError(f"total roll inertia {total_inertia_kg_m2} kg m^2 must be positive")
        return cls(inputs, omega_rad_s, total_inertia_kg_m2, validity(inputs, omega_rad_s))

    def components(self, amplitude_rad: float) -> dict[str, float]:
        """B̂F, B̂W, B̂E, B̂L, B̂BK and B̂44 at amplitude φa (rad)."""
        return components(self.inputs, self.omega_rad_s, amplitude_rad)

    def per_inertia(self, b_hat: float) -> float:
        """A non-dimensional B̂ as damping per unit total inertia, B44 / I (1/s)."""
        return b_hat / self.inputs.hat_factor / self.total_inertia_kg_m2

    def _parts(self, amplitudes_rad: Sequence[float]) -> tuple[list[float], list[dict[str, float]]]:
        """The distinct amplitudes, sorted, and each component per unit inertia (1/s) at each."""
        amplitudes = sorted({float(a) for a in amplitudes_rad})
        rows = [self.components(a) for a in amplitudes]
        return amplitudes, [{k: self.per_inertia(row[k]) for k in COMPONENTS} for row in rows]

    def _fit(self, amplitudes_rad: Sequence[float], keys: Sequence[str]) -> tuple[float, float]:
        return fit_parts(self.omega_rad_s, *self._parts(amplitudes_rad), keys)

    def equivalent_model(self, amplitudes_rad: Sequence[float]) -> dict[str, float]:
        """{"b1", "b2", "c1"} per unit total inertia (1/s, 1/rad, 1/s²): the prediction as a decay model,
        B_eq/I = b1 + 8/(3π) ω φa b2 (ident.derived.b_eq's convention) fitted over the amplitudes."""
        b1, b2 = self._fit(amplitudes_rad, tuple(COMPONENTS))
        return {"b1": b1, "b2": b2, "c1": self.omega_rad_s**2}

    def required_change(
        self, measured_b1: float, measured_b2: float, amplitudes_rad: Sequence[float]
    ) -> list[str]:
        """Which components would have to change, by how much, for the prediction to meet a measured b1, b2
        (``change_lines``)."""
        return change_lines(self.omega_rad_s, *self._parts(amplitudes_rad), measured_b1, measured_b2)

    def summary(self, amplitudes_rad: Sequence[float], scale: FroudeScale | None = None) -> dict[str, Any]:
        """What ``tankdaq predict --json`` prints: the components and B44 at each amplitude (deg at this
        edge), the equivalent model, the validity findings and, with ``scale``, the ship's values."""
        rows = []
        for amplitude in amplitudes_rad:
            found = self.components(amplitude)
            b44 = found[TOTAL] / self.inputs.hat_factor
            rows.append(
                {"amplitude_deg": math.degrees(amplitude), **found, "b44_n_m_s": b44,
                 "b_eq_per_s": b44 / self.total_inertia_kg_m2}
            )  # fmt: skip
        model = self.equivalent_model(amplitudes_rad)
        out: dict[str, Any] = {
            "omega_rad_s": self.omega_rad_s,
            "period_s": 2 * math.pi / self.omega_rad_s,
            "omega_hat": self.inputs.omega_hat(self.omega_rad_s),
            "total_inertia_kg_m2": self.total_inertia_kg_m2,
            "inputs": asdict(self.inputs),
            "amplitudes": rows,
            "equivalent_model": model,
            "validity": [finding.line for finding in self.findings],
        }
        if scale is not None:
            out["full_scale"] = {
                "scale_factor": scale.scale,
                "period_s": scale.time_s(out["period_s"]),
                "equivalent_model": scale.coefficients(model),
                "amplitudes": [
                    {
                        "amplitude_deg": r["amplitude_deg"],
                        "B_44": r[TOTAL],
                        "b44_n_m_s": scale.damping_n_m_s(r["b44_n_m_s"]),
                    }
                    for r in rows
                ],
                "note": FRICTION_NOTE,
            }
        return out


def summary_lines(summary: dict[str, Any]) -> list[str]:
    """``summary`` as text: one row per amplitude, the equivalent model, a warning line per finding."""
    head = "".join(f"{COMPONENTS[k][0]:>11}" for k in COMPONENTS)
    lines = [
        f"roll frequency {summary['omega_rad_s']:.4g} rad/s (period {summary['period_s']:.4g} s, "
        f"ω̂ {summary['omega_hat']:.3g}), total inertia {summary['total_inertia_kg_m2']:.4g} kg m^2",
        "",
        f"  {'amplitude':>10}{head}{'B̂44':>11}{'B44 N·m·s':>12}{'B_eq/I 1/s':>12}",
    ]
    for row in summary["amplitudes"]:
        cells = "".join(f"{row[k]:>11.4g}" for k in (*COMPONENTS, TOTAL))
        lines.append(
            f"  {row['amplitude_deg']:>6.2f} deg{cells}{row['b44_n_m_s']:>12.4g}{row['b_eq_per_s']:>12.4g}"
        )
    model = summary["equivalent_model"]
    lines += [
        "",
        f"  equivalent model per unit inertia: b1 {model['b1']:.5g} 1/s, b2 {model['b2']:.5g} 1/rad, "
        f"c1 {model['c1']:.5g} 1/s^2",
    ]
    ship = summary.get("full_scale")
    if ship is not None:
        scaled = ship["equivalent_model"]
        lines += [
            f"  full scale (1:{ship['scale_factor']:g}): period {ship['period_s']:.4g} s (B̂44 unchanged), "
            f"b1 {scaled['b1']:.5g} 1/s, b2 {scaled['b2']:.5g} 1/rad, c1 {scaled['c1']:.5g} 1/s^2",
            *amplitude_lines(ship),
            f"  note: {ship['note']}",
        ]
    return lines + [f"warning: {line}" for line in summary["validity"]]
