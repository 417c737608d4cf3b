"""Decay models as ordered sets of terms, and the aliases people use for them.

A model is a tuple of term names in the term table's order (damping, restoring,
then the extra effects), e.g. ``("b1", "b2", "c1", "c3")``. ``resolve_model``
accepts a comma list of terms or an alias: the ITTC forms and every formula of
the seed papers, read as documented in docs/models.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import InputError
from .terms import RESTORING_TERMS, TERM_TABLE


@dataclass(frozen=True)
class ModelAlias:
    """A named model: its terms and where the reading comes from."""

    name: str
    terms: tuple[str, ...]
    source: str


def _alias(name: str, terms: str, source: str) -> ModelAlias:
    return ModelAlias(name, tuple(terms.split(",")), source)


#: Every named model; docs/models.md explains each reading.
MODEL_ALIASES: dict[str, ModelAlias] = {
    a.name: a
    for a in (
        _alias("ittc-linear", "b1,c1", "ITTC 7.5-02-07-04.5 eq. 7/11: linear damping and restoring"),
        _alias("ittc-quadratic", "b1,b2,c1", "ITTC eq. 8-9 up to quadratic damping, linear restoring"),
        _alias("ittc-cubic", "b1,b2,b3,c1", "ITTC eq. 9 (Bulian): linear + quadratic + cubic damping"),
        _alias(
            "ittc-quadratic-restoring", "b1,b2,c1,c3", "ITTC eq. 6 + 9: quadratic damping, cubic restoring"
        ),
        _alias("ittc-cubic-restoring", "b1,b2,b3,c1,c3", "ITTC eq. 6 + 9: cubic damping, cubic restoring"),
        _alias("seed000-eq1", "b1,b2,b3,s1", "seed 000 eq. 4.1 (psi^3 read as psi'^3, per eq. 5.1)"),
        _alias("seed000-eq2", "b1,b2,b3,c1,c2", "seed 000 eq. 4.2 (psi^3 read as psi'^3)"),
        _alias("seed000-eq3", "b1,b2,b3,c1,c2,c3", "seed 000 eq. 4.3 (V|psi'| read as V|psi'|psi')"),
        _alias("seed000-eq4", "b1,b2,b3,s1,s2,s3", "seed 000 eq. 4.4 (V|psi'| read as V|psi'|psi')"),
        _alias("seed001-eq1", "b1,b2,b3,c1,c2,c3", "seed 001 eq. 2 (W|phi'| read as W|phi'|phi')"),
        _alias("seed001-eq2", "b1,b2,b3,c1", "seed 001 eq. 3 (Dh phi: linear restoring)"),
        _alias("seed001-eq3", "b1,b2,b3,s1,s2,s3", "seed 001 eq. 4"),
        _alias("seed001-eq4", "b1,b2,b3,s1,s3", "seed 001 eq. 5 ('C1 d sin phi' read as C1 sin^3 phi)"),
        _alias("seed002-eq1", "b1,b2,b3,c1,c2,c3", "seed 002 eq. 1 (lost; from its identified equation)"),
        _alias("seed002-eq2", "b1,b2,b3,c1", "seed 002 eq. 2 (lost; the 'one power' form, variable h)"),
        _alias("seed002-eq3", "b1,b2,b3,s1,s2,s3", "seed 002 eq. 3 (lost; the sinusoid form)"),
    )
}

#: The models ``tankdaq identify --compare`` fits: every seed formula and ITTC form.
COMPARE_MODELS: tuple[str, ...] = tuple(MODEL_ALIASES)

#: What the data choose from (``identify``, sessions, the live refit; ``ident.model_choice``), simplest
#: first: linear, + quadratic damping, + cubic restoring, cubic instead of quadratic damping (the seeds'
#: SWATH), both (docs/models.md). Larger sets are for ``--compare`` and ``diagnose``.
MODEL_FAMILY: tuple[str, ...] = ("b1,c1", "b1,b2,c1", "b1,b2,c1,c3", "b1,b3,c1,c3", "b1,b2,b3,c1,c3")
#: The model word that asks for the data to choose; as a term set it is the family's union (what a
#: recording's fit channel and the live view must be ready to carry).
AUTO = "auto"


def is_auto(model: str | Sequence[str]) -> bool:
    """Whether ``model`` asks for the data to choose among ``MODEL_FAMILY``."""
    return isinstance(model, str) and model.strip().lower() == AUTO


def canonical_order(terms: set[str] | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """Terms sorted into the term table's order, so equal models compare equal."""
    order = list(TERM_TABLE)
    return tuple(sorted(set(terms), key=order.index))


def resolve_model(spec: str | Sequence[str]) -> tuple[str, ...]:
    """``'b1,b2,c1,c3'``, ``'ittc-cubic'`` or ``'seed001-eq1'`` -> ordered term tuple.

    Unknown names raise InputError listing what is accepted, so a typo on the
    command line gets an answer rather than a traceback.
    """
    if is_auto(spec):
        return canonical_order({term for model in MODEL_FAMILY for term in model.split(",")})
    if isinstance(spec, str):
        key = spec.strip().lower()
        if key in MODEL_ALIASES:
            return MODEL_ALIASES[key].terms
        names = [part.strip().lower() for part in key.split(",") if part.strip()]
    else:
        names = [str(part).strip().lower() for part in spec]
    if not names:
        raise InputError("empty model: give terms like b1,b2,c1,c3 or an alias such as ittc-quadratic")
    unknown = [n for n in names if n not in TERM_TABLE]
    if unknown:
        raise InputError(
            f"unknown model term(s) {', '.join(unknown)}: use terms {', '.join(TERM_TABLE)} "
            f"or an alias ({', '.join(MODEL_ALIASES)})"
        )
    if len(set(names)) != len(names):
        raise InputError(f"model {spec!r} names a term twice")
    terms = canonical_order(names)
    if not set(terms) & set(RESTORING_TERMS):
        raise InputError(f"model {spec!r} has no restoring term: a decay needs one of c1, c3, s1 ...")
    return terms


def model_name(terms: tuple[str, ...]) -> str:
    """The aliases of a term set (several seed formulas share one), else the comma list."""
    names = [alias.name for alias in MODEL_ALIASES.values() if alias.terms == tuple(terms)]
    return " = ".join(names) if names else ",".join(terms)
