"""Configuration files under ``configs/``: hulls, vehicles, campaigns (TOML).

Configuration is data, not code. This module finds the folder, parses drafts
written as people write them (``0.9T``, ``T``, ``1.1T``) and loads hulls: a path
given to ``--hull``, else the user's hull folder, else the shipped ones
(docs/hulls.md).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..errors import ConfigError, InputError
from ..physics.decay import decay_refusal
from ..physics.ikeda import IkedaPrediction
from ..physics.scaling import FroudeScale
from ..physics.scenario import SIMULATION_RULE, DecayScenario
from ..physics.terms import TERMS
from .particulars import IKEDA_KEYS, MainParticulars, ikeda_inputs, parse_particulars, plausible
from .particulars import WaterSettings as WaterSettings  # for --full-scale's friction correction
from .particulars import friction_scaling as friction_scaling
from .rules import number, read_toml, refuse_unknown, safe_name, shown, table, text, uncertainty


def config_dir() -> Path:
    """The configs folder: $TANKDAQ_CONFIG_DIR, the source checkout's, or the installed copy."""
    env = os.environ.get("TANKDAQ_CONFIG_DIR")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parents[1]  # the tankdaq package (this is tankdaq/config/hulls.py)
    for candidate in (here.parent.parent / "configs", here / "_configs"):
        if candidate.is_dir():
            return candidate
    raise ConfigError("cannot find the configs folder; set TANKDAQ_CONFIG_DIR to it")


_DRAFT_RE = re.compile(r"^\s*(\d*\.?\d*)\s*[tT]\s*$")


def parse_draft(text: str) -> float:
    """``'1.1T'`` -> 1.1, ``'T'`` -> 1.0. Raises InputError with the accepted forms."""
    m = _DRAFT_RE.match(str(text))
    if not m:
        raise InputError(
            f"draft {text!r} not understood: write a factor of the design draft, e.g. 0.9T, T, 1.1T"
        )
    factor = float(m.group(1)) if m.group(1) not in ("", ".") else 1.0
    if not 0.3 <= factor <= 2.0:
        raise InputError(f"draft {text!r} is outside 0.3T..2.0T; write e.g. 0.9T, T, 1.1T")
    return factor


def format_draft(factor: float) -> str:
    """1.0 -> 'T', 1.1 -> '1.1T' (the inverse of ``parse_draft``)."""
    return "T" if abs(factor - 1.0) < 1e-9 else f"{factor:g}T"


@dataclass
class AxisParticulars:
    """What the model is about one axis: metacentric height and (dry) radius of gyration, if known."""

    axis: str
    gm_m: float | None = None
    radius_of_gyration_m: float | None = None
    note: str = ""
    gm_uncertainty_m: float | None = None  # standard uncertainties (the uncertainty budget's Type B)
    radius_of_gyration_uncertainty_m: float | None = None


@dataclass
class SimulationModel:
    """Decay coefficients of one axis per draft factor: what the simulator plays (``[simulation]``)."""

    axis: str
    drafts: dict[float, dict[str, float]]
    source: str = ""

    def coefficients(self, draft: float) -> dict[str, float]:
        """Coefficients at a draft factor, linearly interpolated between the configured drafts."""
        keys = sorted(self.drafts)
        if draft < keys[0] - 1e-9 or draft > keys[-1] + 1e-9:
            known = ", ".join(format_draft(k) for k in keys)
            raise InputError(f"draft {format_draft(draft)} is outside the configured drafts ({known})")
        for k in keys:
            if abs(k - draft) < 1e-9:
                return dict(self.drafts[k])
        hi = next(k for k in keys if k > draft)
        lo = max(k for k in keys if k < draft)
        w = (draft - lo) / (hi - lo)
        names = set(self.drafts[lo]) | set(self.drafts[hi])
        return {n: (1 - w) * self.drafts[lo].get(n, 0.0) + w * self.drafts[hi].get(n, 0.0) for n in names}


#: Where a hull file was found, in lookup order.
ORIGIN_PATH, ORIGIN_USER, ORIGIN_SHIPPED = "path", "user", "shipped"


@dataclass
class Hull:
    """A model hull: what it is (dimensions, GM, gyradius per axis) and, optionally, how it decays.

    ``simulation`` holds decay coefficients only the simulator needs; a lab's own hull usually has none
    (the coefficients are what the lab is about to measure).
    """

    name: str
    description: str
    dimensions: dict[str, float]
    axes: dict[str, AxisParticulars]
    simulation: dict[str, SimulationModel] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    path: Path | None = None
    origin: str = ORIGIN_SHIPPED
    main_particulars: MainParticulars = field(default_factory=lambda: MainParticulars({}))

    @property
    def displacement_kg(self) -> float | None:
        return self.dimensions.get("displacement_kg")

    @property
    def displacement_uncertainty_kg(self) -> float | None:
        """The displacement's standard uncertainty ``[dimensions] displacement_uncertainty_kg``, if given."""
        return self.dimensions.get("displacement_uncertainty_kg")

    def particulars(self, axis: str) -> AxisParticulars:
        """GM and gyradius of an axis (both None when the file does not give them)."""
        return self.axes.get(axis, AxisParticulars(axis))

    def dry_inertia_kg_m2(self, axis: str) -> float | None:
        """m k^2 from the displacement and the axis' radius of gyration, when both are known."""
        k = self.particulars(axis).radius_of_gyration_m
        return None if k is None or self.displacement_kg is None else self.displacement_kg * k * k

    def simulation_model(self, axis: str) -> SimulationModel:
        """The decay coefficients the simulator plays; a hull without them is refused in one line."""
        if axis not in self.simulation:
            has = (
                f"it has [simulation] for {', '.join(sorted(self.simulation))}"
                if self.simulation
                else ("it has no [simulation] part")
            )
            raise InputError(
                f"hull {self.name!r} has no simulation coefficients for {axis} ({has}): the simulator needs "
                f'them; record from a real port, or add [simulation.{axis}.drafts."T"] to {self.path}'
            )
        return self.simulation[axis]

    def simulated_coefficients(
        self, axis: str, draft: float, rate_hz: float | None = None
    ) -> dict[str, float]:
        """What the simulator plays on ``axis`` at ``draft``, checked to give a decay it can show at
        ``rate_hz`` (``physics.decay.decay_refusal``): refused in one line before anything starts."""
        coefficients = self.simulation_model(axis).coefficients(draft)
        why = decay_refusal(coefficients, rate_hz)
        if why is not None:
            raise InputError(f"hull {self.name} {axis} at {format_draft(draft)}: {SIMULATION_RULE}: {why}")
        return coefficients


def user_hulls_dir() -> Path:
    """The user's hull folder: $TANKDAQ_HULLS_DIR, else $XDG_CONFIG_HOME/tankdaq/hulls (~/.config/...).

    The XDG base-directory rule, as platformdirs applies it on Linux: a relative XDG_CONFIG_HOME is
    ignored. On Windows, %APPDATA%\\tankdaq\\hulls.
    """
    env = os.environ.get("TANKDAQ_HULLS_DIR")
    if env:
        return Path(env).expanduser()
    if os.name == "nt" and os.environ.get("APPDATA"):
        return Path(os.environ["APPDATA"]) / "tankdaq" / "hulls"
    xdg = os.environ.get("XDG_CONFIG_HOME", "")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".config"
    return base / "tankdaq" / "hulls"


def shipped_hulls_dir() -> Path:
    return config_dir() / "hulls"


@dataclass(frozen=True)
class HullEntry:
    """One hull file found by name: where it lives and which folder it came from."""

    name: str
    path: Path
    origin: str
    shadows: Path | None = None  # a shipped hull of the same name that this user hull hides


def find_hulls() -> list[HullEntry]:
    """Every hull known by name: the user's first, then the shipped ones they do not shadow."""
    user = {p.stem: p for p in sorted(user_hulls_dir().glob("*.toml"))}
    shipped = {p.stem: p for p in sorted(shipped_hulls_dir().glob("*.toml"))}
    entries = [HullEntry(n, p, ORIGIN_USER, shipped.get(n)) for n, p in user.items()]
    entries += [HullEntry(n, p, ORIGIN_SHIPPED) for n, p in shipped.items() if n not in user]
    return sorted(entries, key=lambda e: e.name)


def list_hulls() -> list[str]:
    """Names of the hulls found by name (user folder and shipped)."""
    return [entry.name for entry in find_hulls()]


def is_hull_path(spec: str) -> bool:
    """``--hull`` names a file (a .toml, or anything with a folder in it) rather than a hull by name."""
    return spec.endswith(".toml") or "/" in spec or os.sep in spec


def locate_hull(spec: str) -> tuple[Path, str]:
    """(file, origin) of a hull: a path given as is, else the user folder, else the shipped ones."""
    if is_hull_path(spec):
        path = Path(spec).expanduser()
        if not path.is_file():
            raise InputError(f"hull file {spec} does not exist; write one with: tankdaq hulls new NAME")
        return path, ORIGIN_PATH
    for entry in find_hulls():
        if entry.name == spec:
            return entry.path, entry.origin
    known = ", ".join(list_hulls()) or "none"
    raise InputError(
        f"unknown hull {spec!r}; known hulls: {known} (a file path works too; tankdaq hulls new NAME "
        f"writes a template to {user_hulls_dir()})"
    )


def load_hull(spec: str) -> Hull:
    """A hull by path or name (lookup: a path, the user folder, the shipped ones); unknown names list all."""
    path, origin = locate_hull(spec)
    return _parse_hull(read_toml(path), path, origin)


def hull_scenario(
    hull: str | Hull = "swath", draft: float = 1.0, axis: str = "roll", **settings: Any
) -> DecayScenario:
    """A scripted decay test of ``hull`` (name, .toml path or loaded hull) at ``draft`` factor: the
    scenario plays the hull's ``[simulation]`` coefficients for ``axis``; ``settings`` go to
    ``DecayScenario`` (angle_deg, rate_hz, runs, seed...). Physics knows no hull files: this is
    where the two meet."""
    loaded = hull if isinstance(hull, Hull) else load_hull(hull)
    coefficients = loaded.simulated_coefficients(axis, draft, settings.get("rate_hz"))
    return DecayScenario(hull=loaded.name, draft=draft, axis=axis, coefficients=coefficients, **settings)


#: Physical particulars of a hull and their sane ranges (above 0, at most): a model or a ship.
PARTICULAR_RANGES = {"gm_m": 1000.0, "radius_of_gyration_m": 1000.0, "displacement_kg": 1e10}
#: The [dimensions] that are sizes, so above 0 (other keys are kept as given, signs and all).
POSITIVE_DIMENSIONS = {"length_m", "beam_m", "depth_m", "draft_m", "displacement_kg"}
#: The axes a hull's [simulation] part may play.
SIMULATED_AXES = ("roll", "pitch")


def _parse_hull(data: dict[str, Any], path: Path, origin: str) -> Hull:
    """A hull from its TOML, every value checked (names, ranges, drafts, the simulator's coefficients)."""
    axes_table = table(data, "axes", str(path))
    if any(isinstance(spec, dict) and "drafts" in spec for spec in axes_table.values()):
        raise ConfigError(
            f"{path}: decay coefficients belong under [simulation.<axis>.drafts], not [axes.<axis>.drafts] "
            "(hull files now say what the model is; see docs/hulls.md)"
        )
    dimensions = {
        str(key): number(value, f"{path}: dimensions.{key}", -PARTICULAR_RANGES["displacement_kg"],
                         PARTICULAR_RANGES["displacement_kg"])
        for key, value in table(data, "dimensions", str(path)).items()
    }  # fmt: skip
    for key in POSITIVE_DIMENSIONS & set(dimensions):  # sizes results divide by: a 0 is a typo
        number(dimensions[key], f"{path}: dimensions.{key}", 0.0, PARTICULAR_RANGES["displacement_kg"])
    uncertainty(dimensions, "displacement_kg", dimensions, f"{path}: dimensions")
    return Hull(
        name=safe_name(data.get("name", path.stem), f"{path}: hull name"),
        description=text(data, "description", str(path)),
        dimensions=dimensions,
        axes={str(axis): _particulars(axis, spec, path) for axis, spec in axes_table.items()},
        simulation={
            str(axis): _simulation(str(axis), spec, path)
            for axis, spec in table(data, "simulation", str(path)).items()
        },
        sources={str(k): str(v) for k, v in table(data, "sources", str(path)).items()},
        path=path,
        origin=origin,
        main_particulars=parse_particulars(data.get("particulars", {}), path, parse_draft),
    )


def _particulars(axis: str, spec: object, path: Path) -> AxisParticulars:
    where = f"{path}: axes.{axis}"
    if not isinstance(spec, dict):
        raise ConfigError(f"{where} must be a table ([axes.{axis}]), not {shown(spec)}")
    values = {
        key: number(spec[key], f"{where}.{key}", 0.0, PARTICULAR_RANGES[key])
        for key in ("gm_m", "radius_of_gyration_m")
        if spec.get(key) is not None
    }
    uncertain = {key: uncertainty(spec, key, values, where) for key in ("gm_m", "radius_of_gyration_m")}
    return AxisParticulars(
        axis, values.get("gm_m"), values.get("radius_of_gyration_m"), text(spec, "note", where),
        uncertain["gm_m"], uncertain["radius_of_gyration_m"],
    )  # fmt: skip


def _simulation(axis: str, spec: object, path: Path) -> SimulationModel:
    """One axis of [simulation]: known terms, finite numbers, one entry per draft, and a playable decay."""
    where = f"{path}: simulation.{axis}"
    if axis not in SIMULATED_AXES:
        raise ConfigError(f"{where}: the simulator plays {' or '.join(SIMULATED_AXES)}, not {shown(axis)}")
    if not isinstance(spec, dict):
        raise ConfigError(f"{where} must be a table, not {shown(spec)}")
    drafts: dict[float, dict[str, float]] = {}
    written: dict[float, str] = {}
    for draft_text, coeffs in table(spec, "drafts", where).items():
        at = f"{where}.drafts.{shown(draft_text)}"
        try:
            factor = parse_draft(draft_text)
        except InputError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        if factor in written:
            raise ConfigError(
                f"{where}: drafts {written[factor]!r} and {draft_text!r} are the same draft; keep one"
            )
        if not isinstance(coeffs, dict):
            raise ConfigError(f"{at} must be a table of coefficients, not {shown(coeffs)}")
        refuse_unknown(coeffs, TERMS, at)
        values = {k: number(v, f"{at}.{k}", -1e9, 1e9, low_open=False) for k, v in coeffs.items()}
        why = decay_refusal(values)
        if why is not None:
            raise ConfigError(f"{at}: {SIMULATION_RULE}: {why}")
        drafts[factor], written[factor] = values, draft_text
    if not drafts:
        raise ConfigError(f"{path}: [simulation.{axis}] has no drafts (or leave the part out)")
    return SimulationModel(axis=axis, drafts=drafts, source=text(spec, "source", where))


#: A roll period a prediction is made at: a model's (about 0.5-5 s) to a full-scale ship's (about 30 s).
MIN_PERIOD_S, MAX_PERIOD_S = 0.1, 100.0


def ikeda_prediction(
    hull: Hull, draft: float, speed_m_s: float = 0.0, period_s: float | None = None
) -> IkedaPrediction:
    """The simplified Ikeda prediction of a hull's roll damping at a draft factor and carriage speed.

    The roll frequency is 2 pi / ``period_s`` when given, else sqrt(m g GM / I) with the total inertia
    I = m k^2 (1 + added_inertia_fraction) from the roll gyradius; m is the displacement (scaled with
    the draft factor, as the dimensional results do). Missing particulars are named in one line, and
    every number is checked against physics and the others (``config.particulars.plausible``) first.
    """
    p = hull.main_particulars.at(draft)
    where = f"[particulars] of {hull.path or hull.name}"
    missing = [k for k in IKEDA_KEYS if k not in p] + (
        [] if {"kg_m", "og_m"} & set(p) else ["kg_m (or og_m)"]
    )
    if missing:
        raise InputError(
            f"hull {hull.name!r} lacks {', '.join(missing)} for an Ikeda prediction: add them to {where}"
        )
    if abs(draft - 1.0) > 1e-9 and not any(abs(f - draft) < 1e-9 for f in hull.main_particulars.drafts):
        raise InputError(
            f"hull {hull.name!r} gives its particulars at T only: add "
            f'[particulars.drafts."{format_draft(draft)}"] (draft_m, kg_m, ...) to {hull.path or hull.name}'
        )
    checked = plausible(p, hull.main_particulars.values, hull)  # one line before any formula runs
    inputs = ikeda_inputs(p, speed_m_s)
    gm = hull.particulars("roll").gm_m
    mass = (
        hull.displacement_kg * draft
        if hull.displacement_kg
        else p.get("water_density_kg_m3", 1000.0) * inputs.volume_m3
    )
    if gm is None:
        raise InputError(
            f"hull {hull.name!r} lacks gm_m under [axes.roll]: the damping per unit inertia needs it"
        )
    if period_s is not None:
        if not (math.isfinite(period_s) and MIN_PERIOD_S <= period_s <= MAX_PERIOD_S):
            raise InputError(
                f"--period {period_s:g}: give a roll period of {MIN_PERIOD_S:g} to {MAX_PERIOD_S:g} s"
            )
        omega = 2 * math.pi / period_s
        inertia = mass * inputs.g_m_s2 * gm / omega**2
    else:
        k = hull.particulars("roll").radius_of_gyration_m
        if k is None or "added_inertia_fraction" not in p:
            raise InputError(
                f"hull {hull.name!r} needs radius_of_gyration_m under [axes.roll] and added_inertia_fraction "
                f"in {where} for the natural roll frequency; or give the roll period (--period)"
            )
        inertia = mass * k * k * (1.0 + p["added_inertia_fraction"])
        omega = math.sqrt(mass * inputs.g_m_s2 * gm / inertia)
    prediction = IkedaPrediction.at(inputs, omega, inertia)
    return replace(prediction, findings=[*checked, *prediction.findings])


def full_scale_of(hull: Hull | None, asked: bool) -> FroudeScale | None:
    """The hull's Froude scale when ``--full-scale`` is asked (checked before any work), else None."""
    if not asked:
        return None
    if hull is None:
        raise InputError("--full-scale needs --hull (a hull file with scale_factor under [particulars])")
    scale = hull.main_particulars.values.get("scale_factor")
    if scale is None:
        raise InputError(
            f"--full-scale needs scale_factor under [particulars] in {hull.path or hull.name} "
            "(ship length / model length)"
        )
    return FroudeScale(scale)


#: What ``tankdaq hulls new NAME`` writes: every field explained, the coefficients left out.
HULL_TEMPLATE = """\
# Hull file for tankdaq: what the model is. Units SI (m, kg). Lines starting with # are comments.
# Used by: tankdaq record --hull {name}, identify --hull {name}, campaign (dimensional results).
name = "{name}"
description = "{name}: describe the model (scale, owner, loading condition)"

[dimensions]
# Main dimensions of the model as tested. Any key = number is kept in every recording's metadata.
length_m = 1.0
beam_m = 0.3
draft_m = 0.1
# Displacement (mass) at the design draft T: with GM it fixes the total inertia I = m g GM / c1.
displacement_kg = 20.0

[axes.roll]
# Transverse metacentric height GM_T (m) at the design draft.
gm_m = 0.05
# Dry radius of gyration about the roll axis (m), if known: the added inertia fraction is then reported.
# radius_of_gyration_m = 0.12

[axes.pitch]
# Longitudinal metacentric height GM_L (m).
# gm_m = 1.5
# radius_of_gyration_m = 0.25

# [particulars] is optional: the main particulars for tankdaq predict (simplified Ikeda roll damping)
# and for --full-scale results. At the design draft T; other drafts in [particulars.drafts."1.1T"].
# [particulars]
# lpp_m = 1.0                     # length between perpendiculars Lpp
# beam_m = 0.3                    # beam B
# draft_m = 0.1                   # draft d
# block_coefficient = 0.65        # CB = volume / (Lpp B d)
# midship_coefficient = 0.98      # CMID = midship section area / (B d)
# kg_m = 0.09                     # KG above the keel; or og_m = d - KG (waterline to roll axis, down +)
# bilge_keel_length_m = 0.25      # lBK (0 or leave out: no bilge keel)
# bilge_keel_breadth_m = 0.008    # bBK, the bilge keel's height (breadth)
# speed_m_s = 0.0                 # carriage speed of the decay tests
# scale_factor = 40.0             # lambda = ship length / model length
# added_inertia_fraction = 0.15   # added / dry roll inertia (with radius_of_gyration_m: the roll period)
# water_temperature_c = 15.0      # tank water (degC): the model's viscosity, --full-scale's friction
# sea_temperature_c = 15.0        # the ship's sea water (degC) for the friction correction

# [simulation] is optional: decay coefficients per unit total inertia (x'' + b1 x' + b2|x'|x' + c1 x
# + c3 x^3 = 0, rad, s) that only the simulator (record --port sim, simulate) needs. Leave it out for a
# real model: the coefficients are what you are about to measure.
# [simulation.roll.drafts."T"]
# b1 = 0.3
# b2 = 0.02
# c1 = 14.0
# c3 = 60.0
"""


def write_hull_template(name: str, folder: Path | None = None) -> Path:
    """Write a commented template ``<folder>/<name>.toml`` (default the user folder); never overwrite."""
    safe_name(name, "hull name")
    folder = folder or user_hulls_dir()
    path = folder / f"{name}.toml"
    if path.exists():
        raise InputError(f"{path} already exists; edit it, or choose another name")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path.write_text(HULL_TEMPLATE.format(name=name))
    except OSError as exc:
        raise InputError(
            f"cannot write {path}: {exc.strerror}; set TANKDAQ_HULLS_DIR to a writable folder"
        ) from None
    return path
