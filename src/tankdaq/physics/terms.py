"""The term vocabulary of the decay equation: one table, read by everything that names a term.

    x'' + sum_j theta_j * phi_j(x, x', u) = 0      (per unit total inertia, angles in rad)

Each row says what a term is called (its name is tankdaq's public vocabulary: CLI, JSON, MCAP
``/fit``, CSV columns), its kernel code (``ident.kernels.term_eval`` has one branch per code), its
kind, how people read it (``label``, ``form``) and the unit of its coefficient. The nine state terms
b1 ... s3 are the canonical equation; ``fc`` (Coulomb friction ``fc*tanh(x'/eps)``, eps an estimator
setting) and ``ku`` (coupling ``ku*u(t)`` to a measured input channel u) are the extra effects. It sits
in ``physics`` because it is the equation's vocabulary: kernels, views, file schemas, configuration and
validation all read it here, and a new term is one row here plus one branch of ``term_eval``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TermSpec:
    """One term: its name, kernel code, kind, what it is called and its function of state."""

    name: str
    code: int
    kind: str  # "damping", "restoring", "friction" or "exogenous"
    description: str
    form: str  # phi_j with ``{x}`` for the angle, e.g. ``|{x}'|{x}'``
    unit: str  # of the coefficient, per unit total inertia

    def phi(self, x: str = "x") -> str:
        """The term's function of state written with ``x`` for the angle: ``sin(phi)^2``."""
        return self.form.format(x=x)

    @property
    def label(self) -> str:
        """``linear damping  b1*x'``: what tables and the written-out equation call it."""
        return f"{self.description}  {self.name}*{self.phi()}"


def _table(*rows: TermSpec) -> dict[str, TermSpec]:
    assert [row.code for row in rows] == list(range(len(rows))), "codes are the row order"
    return {row.name: row for row in rows}


#: Every term, in the canonical order (damping, restoring, then the extra effects).
TERM_TABLE: dict[str, TermSpec] = _table(
    TermSpec("b1", 0, "damping", "linear damping", "{x}'", "1/s"),
    TermSpec("b2", 1, "damping", "quadratic damping", "|{x}'|{x}'", "1/rad"),
    TermSpec("b3", 2, "damping", "cubic damping", "{x}'^3", "s/rad^2"),
    TermSpec("c1", 3, "restoring", "linear restoring", "{x}", "1/s^2"),
    TermSpec("c2", 4, "restoring", "quadratic restoring", "{x}^2", "1/(rad s^2)"),
    TermSpec("c3", 5, "restoring", "cubic restoring", "{x}^3", "1/(rad^2 s^2)"),
    TermSpec("s1", 6, "restoring", "sine restoring", "sin({x})", "1/s^2"),
    TermSpec("s2", 7, "restoring", "sine-squared restoring", "sin({x})^2", "1/s^2"),
    TermSpec("s3", 8, "restoring", "sine-cubed restoring", "sin({x})^3", "1/s^2"),
    TermSpec("fc", 9, "friction", "Coulomb friction", "tanh({x}'/eps)", "rad/s^2"),
    TermSpec("ku", 10, "exogenous", "exogenous coupling", "u(t)", "rad/(s^2 unit of u)"),
)


def terms_of_kind(*kinds: str) -> tuple[str, ...]:
    """The names of the terms of these kinds, in table order."""
    return tuple(name for name, spec in TERM_TABLE.items() if spec.kind in kinds)


RESTORING_TERMS: tuple[str, ...] = terms_of_kind("restoring")
#: The canonical equation: the terms that are functions of the state alone (b1 ... s3).
TERMS: tuple[str, ...] = terms_of_kind("damping", "restoring")


def equation_text(coefficients: dict[str, float] | None = None, x: str = "x") -> str:
    """The equation written out: with coefficients ``phi'' + 0.0144 phi' - ...  = 0``, else symbolic
    over every term (``x'' + b1 x' + b2 |x'|x' + ... = 0``)."""
    text = f"{x}''"
    if coefficients is None:
        return text + "".join(f" + {name} {spec.phi(x)}" for name, spec in TERM_TABLE.items()) + " = 0"
    for name, value in coefficients.items():
        text += f" {'-' if value < 0 else '+'} {abs(value):.5g} {TERM_TABLE[name].phi(x)}"
    return text + " = 0"
