"""Model specs: term lists, aliases, and one-line errors for the rest."""

from __future__ import annotations

import pytest

from tankdaq.errors import InputError
from tankdaq.physics.models import MODEL_ALIASES, resolve_model


def test_terms_are_put_in_canonical_order():
    assert resolve_model("c3, b1,c1,b2") == ("b1", "b2", "c1", "c3")


@pytest.mark.parametrize(
    ("alias", "terms"),
    [
        ("ittc-linear", ("b1", "c1")),
        ("ittc-quadratic", ("b1", "b2", "c1")),
        ("ittc-cubic", ("b1", "b2", "b3", "c1")),
        ("ittc-cubic-restoring", ("b1", "b2", "b3", "c1", "c3")),
        ("seed001-eq1", ("b1", "b2", "b3", "c1", "c2", "c3")),
        ("seed001-eq2", ("b1", "b2", "b3", "c1")),
        ("seed001-eq4", ("b1", "b2", "b3", "s1", "s3")),
        ("seed000-eq1", ("b1", "b2", "b3", "s1")),
        ("seed002-eq3", ("b1", "b2", "b3", "s1", "s2", "s3")),
    ],
)
def test_aliases(alias, terms):
    assert resolve_model(alias) == terms


def test_every_seed_formula_has_an_alias():
    names = set(MODEL_ALIASES)
    expected = {f"seed000-eq{i}" for i in range(1, 5)} | {f"seed001-eq{i}" for i in range(1, 5)}
    expected |= {f"seed002-eq{i}" for i in range(1, 4)}
    assert expected <= names


@pytest.mark.parametrize("spec", ["b1,q7", "", "b1,b1,c1", "b1,b2", "seed009-eq1"])
def test_bad_specs_raise_input_errors(spec):
    with pytest.raises(InputError):
        resolve_model(spec)
