"""The correction in the form a simulation code takes: added moments in SI at model and full scale.

A comparison finds the missing terms per unit total inertia (x'' + ... = 0).
Times the total inertia I = Delta g GM / c1 (the measured stiffness; it holds
the added inertia, which a dry m k^2 does not) they are the moments a code adds
to its roll equation: B44 linear in N m s, quadratic in N m s^2, and so on.
Full scale follows Froude (time x lambda^0.5, moment x lambda^4): a term in
x'^n scales as lambda^(4 + n/2), so B44 linear x lambda^4.5, quadratic x lambda^5
(lab-practice §1). Skin friction does not follow Froude; the note says so.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from ..config.hulls import Hull
from ..ident.derived import dimensional

#: SI unit of a term times the total inertia, and its Froude exponent (moment lambda^4, rate lambda^-0.5).
SCALING: dict[str, tuple[str, float]] = {
    "b1": ("N m s", 4.5),
    "b2": ("N m s^2", 5.0),
    "b3": ("N m s^3", 5.5),
    "c1": ("N m", 4.0),
    "c2": ("N m", 4.0),
    "c3": ("N m", 4.0),
    "s1": ("N m", 4.0),
    "s2": ("N m", 4.0),
    "s3": ("N m", 4.0),
    "fc": ("N m", 4.0),
}
#: What a code calls the damping and restoring coefficients of each axis.
MOMENT_NAME = {"roll": ("B44", "C44"), "pitch": ("B55", "C55")}


def moment_name(term: str, axis: str) -> str:
    """``B44`` for a damping term of roll, ``C44`` for a restoring one, and the friction moment."""
    damping, restoring = MOMENT_NAME.get(axis, ("B", "C"))
    if term == "fc":
        return "friction moment"
    return damping if term.startswith("b") else restoring


@dataclass
class ScaledTerm:
    """One added term: per unit inertia, at model scale (SI) and at full scale (Froude), when known."""

    term: str
    per_unit_inertia: float
    unit: str
    froude_exponent: float
    model_scale: float | None = None
    full_scale: float | None = None


@dataclass
class Correction:
    """The added terms and the inertia and scale they were made dimensional with (None: not given)."""

    terms: list[ScaledTerm]
    total_inertia_kg_m2: float | None = None
    dry_inertia_kg_m2: float | None = None
    added_inertia_fraction: float | None = None
    scale_factor: float | None = None
    notes: list[str] = field(default_factory=list)


def correction(added: Mapping[str, float], stiffness_1_s2: float, hull: Hull | None, axis: str) -> Correction:
    """``added`` (per unit inertia) times I = Delta g GM / ``stiffness_1_s2``, and Froude-scaled."""
    terms = [ScaledTerm(k, v, *SCALING[k]) for k, v in added.items() if k in SCALING]
    result = Correction(terms)
    gm = hull.particulars(axis).gm_m if hull is not None else None
    if hull is None or hull.displacement_kg is None or gm is None:
        result.notes.append(
            "give --hull with displacement_kg and the axis' gm_m for the moments in SI "
            "(per unit inertia here)"
        )
        return result
    dry = hull.dry_inertia_kg_m2(axis)
    dim = dimensional({"c1": stiffness_1_s2}, hull.displacement_kg, gm, dry)
    result.total_inertia_kg_m2, result.dry_inertia_kg_m2 = dim.total_inertia_kg_m2, dry
    result.added_inertia_fraction = dim.added_inertia_fraction
    how = "I = displacement g GM / c1 from the measured period: the added inertia is in it"
    if dim.added_inertia_fraction is not None:
        how += f" ({100 * dim.added_inertia_fraction:.0f} % over the dry m k^2)"
    result.notes.append(how)
    scale = hull.main_particulars.values.get("scale_factor")
    result.scale_factor = scale
    for term in terms:
        term.model_scale = term.per_unit_inertia * dim.total_inertia_kg_m2
        if scale is not None and term.term != "fc":
            term.full_scale = term.model_scale * scale**term.froude_exponent
    if any(t.term == "fc" for t in terms):
        result.notes.append("dry friction belongs to the model test's rig, not to the ship: no full scale")
    if scale is None:
        result.notes.append("no scale_factor under the hull's [particulars]: model scale only")
    elif any(t.term == "b1" for t in terms):
        result.notes.append(
            "a linear part that is skin friction does not follow Froude scaling (ITTC corrects it)"
        )
    return result
