"""``tankdaq auv ...`` end to end through typer's CliRunner, plus one run of the installed script."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tankdaq.cli import app

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, ["auv", *args])


def assert_one_line_error(result, *fragments: str) -> None:
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), result.output
    assert "Traceback" not in result.output
    for fragment in fragments:
        assert fragment in lines[0]


@pytest.fixture(scope="module")
def records(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("auv")
    paths = {"train": folder / "train.mcap", "test": folder / "heldout.csv"}
    result = run(
        "simulate",
        "--vehicle",
        "nps_auv2",
        "--manoeuvre",
        "zigzag",
        "--delta",
        "15",
        "--theta",
        "10",
        "--noise",
        "realistic",
        "--seed",
        "7",
        "--out",
        str(paths["train"]),
    )
    assert result.exit_code == 0, result.output
    assert "8 plane reversals" in result.output and "noise 1 x realistic" in result.output
    result = run("simulate", "--delta", "10", "--theta", "5", "--noise", "none", "--out", str(paths["test"]))
    assert result.exit_code == 0, result.output
    return paths


@pytest.mark.slow
def test_identify_json_reports_every_derivative_against_the_standard(records):
    result = run("identify", str(records["train"]), "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    rows = {row["derivative"]: row for row in report["derivatives"]}
    assert report["vehicle"] == "nps_auv2" and report["method"] == "lssvm"
    assert rows["M_ds"]["standard"] == -0.041
    dominant = [name for name, row in rows.items() if row["dominant"]]
    assert dominant and all(rows[n]["relative_error"] < 0.10 for n in dominant)
    summary = report["sensitivity_vs_error"]
    assert summary["mean_error_top_half"] < summary["mean_error_bottom_half"]


@pytest.mark.slow
def test_identify_with_gamma_chosen_on_a_held_out_record(records):
    result = run("identify", str(records["train"]), "--holdout", str(records["test"]), "--no-sensitivity")
    assert result.exit_code == 0, result.output
    assert f"(on held-out record {records['test']})" in result.output


@pytest.mark.slow
def test_identify_table_with_ols(records):
    result = run("identify", str(records["test"]), "--method", "ols", "--no-sensitivity")
    assert result.exit_code == 0, result.output
    assert "separate identification by ols" in result.output
    assert "M_uw" in result.output and "Z equation: bias" in result.output


@pytest.mark.slow
def test_sensitivity_ranks_and_marks_dominant_derivatives():
    result = run("sensitivity", "--vehicle", "remus100", "--delta", "10", "--theta", "5", "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["vehicle"] == "remus100" and len(report["ranking"]) == 11
    assert report["dominant"] == [n for n in report["ranking"] if report["index"][n] >= 0.1]
    table = run("sensitivity", "--step", "20")
    assert table.exit_code == 0 and "dominant" in table.output and "+/-20 %" in table.output


@pytest.mark.slow
def test_validate_scores_a_held_out_manoeuvre_and_writes_a_plot(records, tmp_path):
    plot = tmp_path / "validation.png"
    result = run(
        "validate", str(records["train"]), "--test", str(records["test"]), "--plot", str(plot), "--json"
    )
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    r2 = report["r2"]["identified, all derivatives"]
    assert min(r2[s] for s in ("w", "q", "theta", "z")) >= 0.95
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_bad_inputs_get_one_line_and_exit_code_2(records, tmp_path):
    assert_one_line_error(
        run("simulate", "--vehicle", "seaglider", "--out", str(tmp_path / "x.mcap")),
        "unknown vehicle 'seaglider'",
        "nps_auv2",
        "remus100",
    )
    assert_one_line_error(run("simulate", "--manoeuvre", "turn", "--out", str(tmp_path / "x.mcap")), "zigzag")
    assert_one_line_error(run("simulate", "--noise", "loud", "--out", str(tmp_path / "x.mcap")), "--noise")
    assert_one_line_error(run("simulate", "--out", str(tmp_path / "x.txt")), ".mcap or .csv")
    assert_one_line_error(run("identify", str(tmp_path / "absent.mcap")), "no such file")
    assert_one_line_error(run("identify", str(records["train"]), "--method", "svr"), "lssvm or ols")
    flat = tmp_path / "flat.csv"
    flat.write_text(
        "t_s,u_m_s,w_m_s,q_rad_s,theta_rad,z_m,x_m,delta_s_rad\n"
        + "".join(f"{0.1 * i},1.5,0,0,0,0,{0.15 * i},0\n" for i in range(300))
    )
    assert_one_line_error(run("identify", str(flat), "--vehicle", "nps_auv2"), "no stern-plane activity")
    assert_one_line_error(run("identify", str(flat)), "--vehicle")
    partial = tmp_path / "partial.csv"
    partial.write_text("t_s,u_m_s,theta_rad\n0,1.5,0\n0.1,1.5,0\n")
    assert_one_line_error(run("identify", str(partial), "--vehicle", "nps_auv2"), "missing channels")
    assert_one_line_error(
        run("validate", str(records["train"]), "--plot", str(tmp_path / "fit.svg")), "ending in .png"
    )


@pytest.mark.slow
def test_installed_script_reports_bad_input_without_a_traceback(tmp_path):
    script = Path(sys.executable).with_name("tankdaq")
    completed = subprocess.run(
        [str(script), "auv", "identify", str(tmp_path / "absent.mcap")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.returncode == 2
    assert "Traceback" not in completed.stderr and completed.stdout == ""
    assert completed.stderr.strip().count("\n") == 0 and "no such file" in completed.stderr
