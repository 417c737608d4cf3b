"""Issue 23's small truths: what --help shows is what the option takes; hulls new shows its template;
campaign names the folders it read and can stay out of subfolders; the licence ships."""

from __future__ import annotations

import re
from pathlib import Path

import click
import pytest
from typer.main import get_command
from typer.testing import CliRunner

from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.cli import app
from tankdaq.cli.app import DRAFT_METAVAR
from tankdaq.config import validation

runner = CliRunner()
REPO = Path(__file__).resolve().parents[2]


def commands_with(option: str) -> dict[str, click.Command]:
    """Every command (sub-groups included) that has ``option``, by its path."""
    found: dict[str, click.Command] = {}

    def walk(command: click.Command, path: list[str]) -> None:
        if any(option in getattr(param, "opts", ()) for param in command.params):
            found[" ".join(path)] = command
        for name, sub in getattr(command, "commands", {}).items():
            walk(sub, [*path, name])

    walk(get_command(app), [])
    return found


def help_of(path: str) -> str:
    result = runner.invoke(app, [*path.split(), "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    return " ".join(result.stdout.split())  # click wraps the help: compare it as one line


@pytest.mark.slow
def test_every_draft_option_shows_the_forms_it_takes() -> None:
    found = commands_with("--draft")
    assert {"identify", "diagnose", "record", "predict", "simulate", "simulate-campaign"} <= set(found)
    for path in found:
        shown = help_of(path)
        assert f"--draft {DRAFT_METAVAR}" in shown, path
        assert "--draft <float>" not in shown and "--draft FLOAT" not in shown, path
    assert runner.invoke(app, ["predict", "--hull", "swath", "--draft", "1.1T", "--help"]).exit_code == 0


@pytest.mark.slow
def test_every_rate_option_lists_every_accepted_rate() -> None:
    """A device's or a simulation's --rate lists the output rates; the --rate of a command that reads
    files is that file's own sample rate (``cli.options.SampleRate``), any, and says so."""
    found = commands_with("--rate")
    files = {"identify", "diagnose", "report"}
    assert {"record", "simulate", "session"} <= set(found) and files <= set(found)
    assert validation.OUTPUT_RATES_HZ[:5] == (1, 2, 4, 5, 8) and validation.OUTPUT_RATES_HZ[-1] == 400
    for path in files:
        assert "--rate <float range> Sample rate, Hz, of a text export that does not say it" in help_of(path)
    for path in set(found) - files:
        listed = re.search(r"--rate \S+ [^:]*: ([\d, ]+)", help_of(path))
        assert listed is not None, path
        rates = tuple(int(r) for r in listed.group(1).replace(",", " ").split())
        assert rates == validation.OUTPUT_RATES_HZ, path
        for rate in rates:  # each rate listed is one the option takes
            assert validation.output_rate_hz(float(rate)) == rate


@pytest.mark.slow
def test_hulls_new_prints_the_template_it_wrote_then_its_path(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("TANKDAQ_HULLS_DIR", str(tmp_path))
    result = runner.invoke(app, ["hulls", "new", "mymodel"])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    written = tmp_path / "mymodel.toml"
    assert lines[-1] == str(written)
    assert lines[:-1] == written.read_text().splitlines()
    assert 'name = "mymodel"' in lines and any(line.startswith("[dimensions]") for line in lines)


@pytest.mark.slow
def test_campaign_names_the_folders_read_and_no_recurse_stays_out_of_subfolders(tmp_path: Path) -> None:
    top = tmp_path / "campaign"
    mine = top / "mine"
    write_simulated_campaign(top, ["trimaran"], "pitch", [1.0], [6.0], "csv", seed=3)
    write_simulated_campaign(mine, ["catamaran"], "pitch", [1.0], [6.0], "csv", seed=4)

    result = runner.invoke(app, ["campaign", str(top), "--no-recurse", "--jobs", "1"])
    assert result.exit_code == 0, result.output
    assert f"read 1 recording(s) from 1 folder(s): {top}\n" in result.stderr
    assert "| trimaran" in result.stdout and "catamaran" not in result.stdout

    pooled = runner.invoke(app, ["campaign", str(top), "--jobs", "1"])
    assert pooled.exit_code == 0, pooled.output
    assert f"read 2 recording(s) from 2 folder(s): {top}, {mine}\n" in pooled.stderr
    assert "| trimaran" in pooled.stdout and "| catamaran" in pooled.stdout


def test_the_licence_is_mit_and_is_packaged() -> None:
    licence = (REPO / "LICENSE").read_text()
    assert licence.startswith("MIT License") and "Copyright (c) 2026 tankdaq authors" in licence
    pyproject = (REPO / "pyproject.toml").read_text()
    assert 'license = "MIT"' in pyproject or 'license = { text = "MIT" }' in pyproject
    assert 'license-files = ["LICENSE"]' in pyproject
