"""Configuration files under ``configs/``: hulls, vehicles, campaigns (TOML).

Configuration is data, not code. This module finds the folder, parses drafts
written as people write them (``0.9T``, ``T``, ``1.1T``) and loads hulls.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .errors import ConfigError, InputError
from .physics.decay import TERMS


def config_dir() -> Path:
    """The configs folder: $TANKDAQ_CONFIG_DIR, the source checkout's, or the installed copy."""
    env = os.environ.get("TANKDAQ_CONFIG_DIR")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent
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
class AxisModel:
    """Decay coefficients of one axis of one hull, per draft factor."""

    axis: str
    drafts: dict[float, dict[str, float]]
    gm_m: float | None = None
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


@dataclass
class Hull:
    """A model hull: main dimensions and the decay model of each axis."""

    name: str
    description: str
    dimensions: dict[str, float]
    axes: dict[str, AxisModel]
    sources: dict[str, str] = field(default_factory=dict)
    path: Path | None = None

    @property
    def displacement_kg(self) -> float | None:
        return self.dimensions.get("displacement_kg")

    def axis_model(self, axis: str) -> AxisModel:
        if axis not in self.axes:
            raise InputError(
                f"hull {self.name!r} has no {axis} model; it has: {', '.join(sorted(self.axes))}"
            )
        return self.axes[axis]


def list_hulls() -> list[str]:
    """Names of the hulls in configs/hulls."""
    return sorted(p.stem for p in (config_dir() / "hulls").glob("*.toml"))


def load_hull(name: str) -> Hull:
    """Load ``configs/hulls/<name>.toml``; an unknown name lists the known ones."""
    path = config_dir() / "hulls" / f"{name}.toml"
    if not path.is_file():
        raise InputError(f"unknown hull {name!r}; known hulls: {', '.join(list_hulls()) or 'none'}")
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, OSError) as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    axes: dict[str, AxisModel] = {}
    for axis, spec in data.get("axes", {}).items():
        drafts: dict[float, dict[str, float]] = {}
        for draft_text, coeffs in spec.get("drafts", {}).items():
            unknown = set(coeffs) - set(TERMS)
            if unknown:
                raise ConfigError(f"{path}: unknown terms {sorted(unknown)} in {axis} {draft_text}")
            drafts[parse_draft(draft_text)] = {k: float(v) for k, v in coeffs.items()}
        if not drafts:
            raise ConfigError(f"{path}: axis {axis} has no drafts")
        axes[axis] = AxisModel(axis=axis, drafts=drafts, gm_m=spec.get("gm_m"), source=spec.get("source", ""))
    return Hull(
        name=data.get("name", name),
        description=data.get("description", ""),
        dimensions={k: float(v) for k, v in data.get("dimensions", {}).items()},
        axes=axes,
        sources=dict(data.get("sources", {})),
        path=path,
    )


@dataclass
class CampaignPlan:
    """A test matrix: which hulls, axis, drafts and initial angles a campaign covers."""

    name: str
    description: str
    hulls: list[str]
    axis: str
    drafts: list[str]
    angles_deg: list[float]


def list_campaign_plans() -> list[str]:
    """Names of the test matrices in configs/campaigns."""
    return sorted(p.stem for p in (config_dir() / "campaigns").glob("*.toml"))


def load_campaign_plan(name: str) -> CampaignPlan:
    """Load ``configs/campaigns/<name>.toml``; an unknown name lists the known ones."""
    path = config_dir() / "campaigns" / f"{name}.toml"
    if not path.is_file():
        raise InputError(
            f"unknown campaign plan {name!r}; known: {', '.join(list_campaign_plans()) or 'none'}"
        )
    try:
        data = tomllib.loads(path.read_text())
        return CampaignPlan(
            name=name,
            description=str(data.get("description", "")),
            hulls=[str(h) for h in data["hulls"]],
            axis=str(data["axis"]),
            drafts=[str(d) for d in data["drafts"]],
            angles_deg=[float(a) for a in data["angles_deg"]],
        )
    except (tomllib.TOMLDecodeError, KeyError, TypeError, ValueError) as exc:
        raise ConfigError(f"{path}: {exc} (needs hulls, axis, drafts, angles_deg)") from None
