"""One default model everywhere (issue 37 item 5): ``demo``, ``identify``, ``campaign`` and the guided
session's report fit the same decays with the same model, chosen by the data in one place
(``ident.model_choice.model_for``), and say which and why; a named model only when asked.

The demo records one decay of the simulated SWATH end to end (the simulator on its pty, about 7 s); the
other commands then read that recording.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tankdaq.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """``tankdaq demo`` with its default model: its folder and what it printed."""
    folder = tmp_path_factory.mktemp("demo")
    demo = ["demo", "--out", str(folder), "--runs", "1", "--sim-speed", "10", "--seed", "0"]  # one decay
    done = runner.invoke(app, demo)
    assert done.exit_code == 0, done.output
    return folder, done.stdout


def _close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)


@pytest.mark.slow
def test_demo_identify_and_campaign_report_one_model_and_the_same_numbers(demo: tuple[Path, str]) -> None:
    folder, demo_out = demo
    (recording,) = sorted(folder.glob("*.mcap"))
    identified = runner.invoke(app, ["identify", str(recording), "--json"])
    assert identified.exit_code == 0, identified.output
    fit = json.loads(identified.stdout)
    chosen = fit["model_choice"]
    assert chosen["chosen"] == ",".join(fit["model"]["terms"]) and "chosen by data" in chosen["reason"]
    assert len(chosen["scores"]) > 1  # the data chose among the family, not a name
    coefficients = {term: entry["value"] for term, entry in fit["coefficients"].items()}

    # the demo prints identify's own report of the same recording: the same model, the same numbers
    as_text = runner.invoke(app, ["identify", str(recording)])
    assert as_text.exit_code == 0, as_text.output
    assert as_text.stdout.strip() in demo_out
    assert f"model {chosen['chosen']}" in demo_out and "seed001-eq1" not in demo_out.split("identified vs")[0]

    grouped = runner.invoke(app, ["campaign", str(folder), "--json", "--jobs", "1"])
    assert grouped.exit_code == 0, grouped.output
    (group,) = json.loads(grouped.stdout)["groups"]
    assert group["model"] == chosen["chosen"] and group["model_reason"] == chosen["reason"]
    assert f"{chosen['reason']}" in grouped.stderr  # said, as identify says it
    assert {term for term in coefficients} <= set(group)
    for term, value in coefficients.items():
        assert _close(group[term], value), (term, group[term], value)


@pytest.mark.slow
def test_the_session_report_fits_the_model_identify_chose(demo: tuple[Path, str], tmp_path: Path) -> None:
    from tankdaq.session.report import write_session_report

    folder, _ = demo
    (recording,) = sorted(folder.glob("*.mcap"))
    fit = json.loads(runner.invoke(app, ["identify", str(recording), "--json"]).stdout)
    written = write_session_report([recording], tmp_path / "report", "auto", "swath")
    with next(path for path in written if path.name == "campaign.csv").open() as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["model"] == fit["model_choice"]["chosen"]
    report = (tmp_path / "report" / "campaign.md").read_text()
    assert f"- swath roll T 8 deg: {fit['model_choice']['reason']}" in report  # which model, and why
    assert "## IMO table" in report and "Bertin's N (MSC.1/Circ.1200), swath roll T" in report  # and N
    assert "## Uncertainty budget" in report and "U (k=2, ≈95 %, expanded)" in report  # each condition's
    with next(path for path in written if path.name == "budget.csv").open() as fh:
        period = [r for r in csv.DictReader(fh) if r["quantity"] == "natural period"]
    assert period[0]["kind"] == "A" and float(period[0]["expanded_u"]) == 2 * float(period[0]["combined_u"])
    said = next(b for b in fit["budget"] if b["key"] == "natural_period_s")
    assert float(period[0]["value"]) == pytest.approx(said["value"], rel=1e-6)
    for term, entry in fit["coefficients"].items():
        assert _close(float(row[term]), entry["value"]), term


@pytest.mark.slow
def test_a_named_model_is_used_only_when_asked_and_says_so(demo: tuple[Path, str]) -> None:
    folder, _ = demo
    grouped = runner.invoke(app, ["campaign", str(folder), "--json", "--model", "seed001-eq1"])
    assert grouped.exit_code == 0, grouped.output
    (group,) = json.loads(grouped.stdout)["groups"]
    assert group["model"] == "b1,b2,b3,c1,c2,c3"
    assert group["model_reason"].endswith("given by --model") and "seed001-eq1" in group["model_reason"]
    (recording,) = sorted(folder.glob("*.mcap"))
    named = runner.invoke(app, ["identify", str(recording), "--json", "--model", "b1,c1"])
    identified = json.loads(named.stdout)
    assert identified["model_choice"] == {"chosen": "b1,c1", "reason": "model ittc-linear given by --model"}
