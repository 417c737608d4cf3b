"""What an uncertainty budget propagates: the device's figures, the hull's uncertainties, the quantities.

A budget (``ident.budget``) evaluates each reported quantity as a function of the fitted coefficients and
of a few inputs known only to an uncertainty (GUM: the measurement model). The inputs are:

- the angle's scale ``angle_scale`` (1 nominal): the device's roll/pitch accuracy and resolution at the
  held tilt, over the decay's initial angle, is how well the decay's amplitudes are known;
- the time base ``time_scale`` (1 nominal): the device clock's accuracy and the resolution of
  SampleTimeFine (0.1 ms) over the decay's duration;
- the hull's GM, displacement and roll gyradius, where the hull file gives them with an uncertainty.

Measured coefficients are those of the equation in measured angle and time; the true ones follow from the
scales by each term's units (``TERM_SCALING``): B_eq/I, say, moves with the time base, b2 with the angle.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from enum import Enum
from functools import partial

from .derived import G, b_eq, bertin_n_per_deg, linear_stiffness, natural_period


class EvaluationType(Enum):
    """GUM's two ways of evaluating a standard uncertainty."""

    A = "A"  # from a series of observations: repeat decays, or the fit's own residuals
    B = "B"  # from other knowledge: a datasheet, a hull file, the clock


@dataclass(frozen=True)
class DeviceProfile:
    """The device's figures a budget uses (Type B), with where they come from; a lab overrides them with
    its own calibration (``DeviceProfile(...)`` given to ``tankdaq.identify(device=...)``).

    ``angle_accuracy_deg`` is the datasheet's dynamic roll/pitch accuracy, an RMS figure and so taken as a
    standard uncertainty; the resolution is a quantisation step (standard uncertainty step/sqrt(12)).
    """

    name: str
    angle_accuracy_deg: float
    angle_resolution_deg: float
    clock_ppm: float
    time_resolution_s: float
    source: str


#: The MTi-G-710 (MTi 100-series, 5th generation) tankdaq was built for.
MTI_G_710 = DeviceProfile(
    name="MTi-G-710",
    angle_accuracy_deg=0.3,
    angle_resolution_deg=0.01,
    clock_ppm=10.0,
    time_resolution_s=1e-4,
    source=(
        "Xsens MTi 100-series datasheet / MTi User Manual MT0605P: roll/pitch 0.2 deg RMS static, "
        "0.3 deg RMS dynamic (the dynamic figure used), clock 10 ppm; SampleTimeFine 0.1 ms; angle "
        "resolution 0.01 deg as recorded files hold it (reference lab-practice §6)"
    ),
)
#: The 2007-era MTi-G (legacy MTData).
MTI_G_LEGACY = DeviceProfile(
    name="MTi-G (legacy)",
    angle_accuracy_deg=1.0,
    angle_resolution_deg=0.05,
    clock_ppm=10.0,
    time_resolution_s=1e-4,
    source=(
        "Xsens MTi-G User Manual MT0137P: roll/pitch < 0.5 deg static, 1 deg RMS dynamic (used), angular "
        "resolution 0.05 deg; clock as the MTi 100-series"
    ),
)


def with_accuracy(accuracy_deg: float, base: DeviceProfile = MTI_G_710) -> DeviceProfile:
    """``base`` with a lab's own roll/pitch accuracy (``identify --angle-accuracy``), its source said."""
    return replace(
        base, name=f"{base.name}, the lab's accuracy", angle_accuracy_deg=accuracy_deg,
        source=f"the lab's --angle-accuracy {accuracy_deg:g} deg; the rest: {base.source}",
    )  # fmt: skip


def device_profile(product_code: str | None) -> DeviceProfile:
    """The profile of the device that says it is ``product_code``: the MTi-G-710's unless the code is the
    legacy MTi-G's (``MTi-G`` alone, or ``MTi-G-28...``); no code (a CSV file) is taken as an MTi-G-710."""
    code = (product_code or "").strip()
    legacy = code.startswith("MTi-G") and not code.startswith(("MTi-G-7", "MTi-G-6"))
    return MTI_G_LEGACY if legacy else MTI_G_710


#: Each term's (time, angle) exponents: true = measured * time_scale**a * angle_scale**p, from its units
#: (b1 1/s: a = 1; b2 1/rad: p = 1; c3 1/(rad^2 s^2): a = 2, p = 2; fc rad/s^2: a = 2, p = -1).
TERM_SCALING = {
    "b1": (1, 0),
    "b2": (0, 1),
    "b3": (-1, 2),
    "c1": (2, 0),
    "c2": (2, 1),
    "c3": (2, 2),
    "s1": (2, 0),
    "s2": (2, 1),
    "s3": (2, 2),
    "fc": (2, -1),
    "ku": (2, -1),
}


def true_coefficients(measured: Mapping[str, float], inputs: Mapping[str, float]) -> dict[str, float]:
    """The coefficients in true angle and time given the measured ones and the scales in ``inputs``."""
    tau, scale = inputs["time_scale"], inputs["angle_scale"]
    return {k: v * tau ** TERM_SCALING[k][0] * scale ** TERM_SCALING[k][1] for k, v in measured.items()}


@dataclass(frozen=True)
class Source:
    """One Type B input's standard uncertainty ``u`` in ``unit``; ``per_unit`` converts one ``unit`` into
    the input ``input`` of the measurement model (1/initial angle for a degree of angle, 1e-6 for ppm)."""

    name: str
    u: float
    unit: str
    input: str
    per_unit: float = 1.0
    note: str = ""


@dataclass(frozen=True)
class HullFigures:
    """The hull's numbers a budget needs at the fitted draft (None: not given), with their uncertainties."""

    gm_m: float | None = None
    gm_u: float | None = None
    displacement_kg: float | None = None
    displacement_u: float | None = None
    gyradius_m: float | None = None
    gyradius_u: float | None = None
    added_inertia_fraction: float | None = None
    hat_factor_per_kg: float | None = None  # B̂44 per B44 times the displacement: sqrt(B/2g) / B^2
    scale_factor: float | None = None


def device_sources(profile: DeviceProfile, initial_deg: float, duration_s: float) -> list[Source]:
    """The device's Type B sources for decays from ``initial_deg`` lasting ``duration_s``."""
    per_deg = 1.0 / initial_deg
    return [
        Source(
            f"angle accuracy ({profile.name})",
            profile.angle_accuracy_deg,
            "deg",
            "angle_scale",
            per_deg,
            profile.source,
        ),
        Source(
            f"angle resolution ({profile.name})",
            profile.angle_resolution_deg / math.sqrt(12),
            "deg",
            "angle_scale",
            per_deg,
            "quantisation step / sqrt(12)",
        ),
        Source("clock", profile.clock_ppm, "ppm", "time_scale", 1e-6, "the device clock's accuracy"),
        Source(
            "time resolution",
            profile.time_resolution_s / math.sqrt(12) * math.sqrt(2),
            "s",
            "time_scale",
            1.0 / duration_s,
            "SampleTimeFine step / sqrt(12) at both ends of the decay",
        ),
    ]


def hull_sources(hull: HullFigures) -> list[Source]:
    """The hull file's uncertainties (``gm_uncertainty_m`` ...) as Type B sources; absent ones add none."""
    given = [
        ("GM", hull.gm_u, "m", "gm_m"),
        ("displacement", hull.displacement_u, "kg", "displacement_kg"),
        ("roll gyradius", hull.gyradius_u, "m", "radius_of_gyration_m"),
    ]
    return [Source(name, u, unit, key, 1.0, "the hull file") for name, u, unit, key in given if u]


def nominal_inputs(hull: HullFigures) -> dict[str, float]:
    """The measurement model's inputs at their nominal values (NaN where the hull does not give them)."""
    nan = math.nan
    return {
        "angle_scale": 1.0,
        "time_scale": 1.0,
        "gm_m": nan if hull.gm_m is None else hull.gm_m,
        "displacement_kg": nan if hull.displacement_kg is None else hull.displacement_kg,
        "radius_of_gyration_m": nan if hull.gyradius_m is None else hull.gyradius_m,
    }


#: A quantity's value from the true coefficients and the inputs.
QuantityFn = Callable[[Mapping[str, float], Mapping[str, float]], float]


@dataclass(frozen=True)
class Quantity:
    """A reported quantity: its name, its unit, its key in JSON and tables, and how it is computed."""

    name: str
    unit: str
    key: str
    fn: QuantityFn
    amplitude_deg: float | None = None


def _period(c: Mapping[str, float], _: Mapping[str, float]) -> float:
    return natural_period(c)


def _stiffness(c: Mapping[str, float], _: Mapping[str, float]) -> float:
    return linear_stiffness(c)


def _term(c: Mapping[str, float], _: Mapping[str, float], term: str) -> float:
    return c[term]


def _gm_implied(c: Mapping[str, float], x: Mapping[str, float], added: float) -> float:
    """GM = c1 k^2 (1 + added) / g: what the decay says of GM given the gyradius and added inertia."""
    return linear_stiffness(c) * x["radius_of_gyration_m"] ** 2 * (1.0 + added) / G


def _b_eq(c: Mapping[str, float], _: Mapping[str, float], amplitude: float) -> float:
    return b_eq(c, amplitude)


def _bertin(c: Mapping[str, float], _: Mapping[str, float], amplitude: float) -> float:
    return bertin_n_per_deg(c, amplitude)


def _b44(c: Mapping[str, float], x: Mapping[str, float], amplitude: float) -> float:
    """B44 = B_eq/I * I, I = Delta g GM / c1 (N m s/rad)."""
    return b_eq(c, amplitude) * x["displacement_kg"] * G * x["gm_m"] / linear_stiffness(c)


def _b44_hat(c: Mapping[str, float], x: Mapping[str, float], amplitude: float, factor: float) -> float:
    return _b44(c, x, amplitude) * factor / x["displacement_kg"]


def _full_scale_b44(c: Mapping[str, float], x: Mapping[str, float], amplitude: float, scale: float) -> float:
    return _b44(c, x, amplitude) * scale**4.5


def reported_quantities(
    terms: Sequence[str], axis: str, amplitudes_deg: Sequence[float], hull: HullFigures
) -> list[Quantity]:
    """Every quantity a fit reports that its terms and hull allow: the natural period, c1 (and the GM it
    implies with the gyradius and added inertia), b1 and b2, and at each amplitude B_eq/I, Bertin's N,
    B̂44 (roll, with GM, displacement and beam) and the full-scale B44 (with a scale factor)."""
    out = [
        Quantity("natural period", "s", "natural_period_s", _period),
        Quantity("c1 + s1 (omega_0^2)", "1/s^2", "c1", _stiffness),
    ]
    if hull.gyradius_m is not None and hull.added_inertia_fraction is not None:
        out.append(
            Quantity(
                "GM implied", "m", "gm_implied_m", partial(_gm_implied, added=hull.added_inertia_fraction)
            )
        )
    out += [
        Quantity(term, unit, term, partial(_term, term=term))
        for term, unit in (("b1", "1/s"), ("b2", "1/rad"))
        if term in terms
    ]
    inertia = hull.gm_m is not None and hull.displacement_kg is not None
    for a_deg in amplitudes_deg:
        a = math.radians(a_deg)
        at = f"at {a_deg:g} deg"
        out.append(
            Quantity(f"B_eq/I {at}", "1/s", f"b_eq_per_s@{a_deg:g}", partial(_b_eq, amplitude=a), a_deg)
        )
        out.append(
            Quantity(
                f"Bertin N {at}", "1/deg", f"bertin_n_per_deg@{a_deg:g}", partial(_bertin, amplitude=a), a_deg
            )
        )
        if inertia and axis == "roll" and hull.hat_factor_per_kg is not None:
            fn = partial(_b44_hat, amplitude=a, factor=hull.hat_factor_per_kg)
            out.append(Quantity(f"B̂44 {at}", "-", f"b44_hat@{a_deg:g}", fn, a_deg))
        if inertia and hull.scale_factor is not None:
            fn = partial(_full_scale_b44, amplitude=a, scale=hull.scale_factor)
            name = f"full-scale {'B44' if axis == 'roll' else 'B55'} {at}"
            out.append(Quantity(name, "N·m·s/rad", f"full_scale_b44_n_m_s@{a_deg:g}", fn, a_deg))
    return out


def reference_amplitudes(tested_deg: Sequence[float]) -> list[float]:
    """The amplitudes a budget is stated at: whole multiples of 5 deg inside the tested band, else the
    band's middle (to 0.5 deg); none without a band."""
    if not tested_deg:
        return []
    lo, hi = min(tested_deg), max(tested_deg)
    fives = [5.0 * k for k in range(math.ceil(lo / 5.0), math.floor(hi / 5.0) + 1) if k > 0]
    return fives or [round((lo + hi) / 2 * 2) / 2]
