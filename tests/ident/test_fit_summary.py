"""A fit's summary crosses rooms typed (issue 43 item 5): ``FitSummary`` is frozen and its ``to_dict`` is
the object ``identify --json`` prints, keys in their order; states are enums whose files hold plain text."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

import tankdaq
from tankdaq.api.identification import to_json
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.ident.free_decay import EndKind
from tankdaq.ident.summary import Coefficient, FitSummary
from tankdaq.physics.scenario import DecayScenario
from tankdaq.physics.truth import RunKind

TERMS = ("b1", "b2", "c1")
#: The order of ``identify --json``'s keys for one condition fitted with a hull (as it always was).
KEYS = [
    "model", "method", "axis", "coefficients", "intervals", "interval_labels", "offset_deg",
    "natural_period_s", "damping_ratio", "seed_objective", "r2_angle", "nrmse", "bic", "runs", "b_eq",
    "bertin_n", "extinction", "plausibility", "warnings", "elapsed_s", "dimensional", "condition_label",
    "model_choice", "budget", "condition", "truncated", "truncated_files",
]  # fmt: skip


@pytest.fixture(scope="module")
def decays(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("swath")
    return write_simulated_campaign(folder, ["swath"], "roll", [1.0], [4.0, 8.0], seed=3)


@pytest.fixture(scope="module")
def with_hull(decays: list[Path]) -> tankdaq.Identification:
    return tankdaq.identify(decays, model=",".join(TERMS), hull="swath")


def test_the_summary_is_typed_and_frozen(with_hull: tankdaq.Identification) -> None:
    (fit,) = with_hull.fits
    summary = fit.summary
    assert isinstance(summary, FitSummary) and summary.model.terms == TERMS
    assert all(isinstance(c, Coefficient) for c in summary.coefficients.values())
    assert summary.values == {term: c.value for term, c in summary.coefficients.items()}
    assert summary.condition_label == fit.label and summary.model_choice is not None
    assert summary.model_choice.terms == TERMS
    with pytest.raises(dataclasses.FrozenInstanceError):
        summary.method = "ee"  # type: ignore[misc]


def test_its_json_is_the_document_identify_prints_keys_in_order(with_hull: tankdaq.Identification) -> None:
    printed = json.loads(with_hull.to_json())
    assert list(printed) == KEYS
    summary = json.loads(to_json(with_hull.fits[0].summary.to_dict()))
    assert printed == summary | {"truncated": False, "truncated_files": []}
    assert printed["model"]["terms"] == list(TERMS) and printed["condition"]["hull"] == "swath"


def test_b44_hat_is_there_only_where_the_hull_gives_it(
    with_hull: tankdaq.Identification, decays: list[Path]
) -> None:
    hulled = with_hull.fits[0].summary
    assert all(row.b44_hat is not None for row in hulled.b_eq)
    assert all("b44_hat" in row for row in hulled.to_dict()["b_eq"])
    bare = tankdaq.identify(decays, model=",".join(TERMS)).fits[0].summary
    assert all(row.b44_hat is None for row in bare.b_eq) and bare.dimensional is None
    written = bare.to_dict()
    assert "dimensional" not in written and all("b44_hat" not in row for row in written["b_eq"])
    assert [row.value_per_s for row in bare.b_eq] == [row.value_per_s for row in hulled.b_eq]


def test_enum_states_are_plain_text_in_what_is_written(with_hull: tankdaq.Identification) -> None:
    cut = with_hull.fits[0].runs[0].meta["cut"]
    assert type(cut["kind"]) is str and cut["kind"] in set(EndKind)
    trace = DecayScenario(runs=1, seed=4, decay_s=5.0, coefficients={"b1": 0.2, "c1": 40.0}).trace()
    assert trace.runs[0].kind is RunKind.RELEASE
    assert type(trace.runs[0].to_json()["kind"]) is str
