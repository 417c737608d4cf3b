"""tankdaq identify end to end: JSON shape, the text report, --compare, and one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from support.held_tilt import write_held_tilt_csv
from tankdaq.cli import app

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, ["identify", *map(str, args)])


@pytest.mark.slow
def test_json_has_the_documented_shape(tmp_path):
    result = invoke(write_held_tilt_csv(tmp_path / "a.csv"), "--model", "ittc-quadratic", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["model"]["terms"] == ["b1", "b2", "c1"]
    assert set(out["coefficients"]) == {"b1", "b2", "c1"}
    for entry in out["coefficients"].values():
        assert (
            set(entry) >= {"value", "std", "ci95"} and entry["ci95"][0] <= entry["value"] <= entry["ci95"][1]
        )
    assert out["coefficients"]["c1"]["value"] == pytest.approx(14.0, rel=1e-3)
    for key in ("offset_deg", "natural_period_s", "damping_ratio", "seed_objective", "r2_angle", "nrmse"):
        assert key in out
    assert out["natural_period_s"] == pytest.approx(2 * np.pi / np.sqrt(14.0), rel=1e-3)
    assert out["runs"][0]["initial_angle_deg"] == pytest.approx(8.0, abs=0.05)
    assert out["runs"][0]["r2_angle"] > 0.9999
    assert [p["amplitude_deg"] for p in out["b_eq"]] == [p["amplitude_deg"] for p in out["bertin_n"]]
    assert isinstance(out["warnings"], list) and out["elapsed_s"] > 0


@pytest.mark.slow
def test_text_report_writes_out_the_equation_and_dimensional_results(tmp_path):
    result = invoke(write_held_tilt_csv(tmp_path / "a.csv"), "--model", "b1,b2,c1", "--hull", "swath")
    assert result.exit_code == 0, result.output
    assert "phi'' + " in result.stdout and "|phi'|phi'" in result.stdout
    assert "total inertia" in result.stdout


@pytest.mark.slow
def test_compare_ranks_every_model_with_held_out_error(tmp_path):
    files = [write_held_tilt_csv(tmp_path / f"{i}.csv", angle0_deg=a) for i, a in enumerate((8.0, 5.0))]
    result = invoke(*files, "--compare", "--json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)["compare"]
    named = {name for row in rows for name in row["models"]}
    assert {"ittc-linear", "seed001-eq1", "seed000-eq4", "seed002-eq2"} <= named
    assert all(row["held_out_rms_deg"] is not None for row in rows)
    bics = [row["bic"] for row in rows]
    assert bics == sorted(bics)


@pytest.mark.parametrize(
    "args",
    [
        ("missing.csv",),
        ("{good}", "--model", "b1,zz"),
        ("{good}", "--method", "nope"),
        ("{good}", "--axis", "yaw"),
        ("{good}", "--angle-unit", "grad"),
        ("{good}", "--angle-col", "phi"),
        ("{good}", "--rate-col", "gyro_deg_s"),
        ("{good}", "--hull", "titanic"),
        ("{good}", "--method", "ee", "--bootstrap", "3"),
        ("{flat}",),
        ("{parquet}",),
    ],
)
@pytest.mark.slow
def test_bad_input_exits_2_with_one_line_and_no_traceback(tmp_path, args):
    good = write_held_tilt_csv(tmp_path / "good.csv")
    parquet = good.rename(tmp_path / "good.parquet") if "{parquet}" in args else None
    flat = tmp_path / "flat.csv"
    flat.write_text("time_s,angle_deg\n" + "".join(f"{i / 100},0.0001\n" for i in range(100)))
    result = invoke(*(a.format(good=good, flat=flat, parquet=parquet) for a in args))
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr


@pytest.mark.slow
def test_mcap_recordings_are_read_through_the_store_reader(tmp_path):
    pytest.importorskip(
        "tankdaq.store.reader", reason="the MCAP reader (store room) is not in this build yet"
    )
    from tankdaq.physics.decay import simulate_decay
    from tankdaq.samples import SAMPLE_DTYPE
    from tankdaq.store.writer import RecordingWriter

    truth = {"b1": 0.4, "b2": 0.5, "c1": 20.0, "c3": 30.0}
    t = np.arange(0.0, 12.0, 0.01)
    free = t >= 2.0
    samples = np.zeros(t.size, dtype=SAMPLE_DTYPE)
    samples["t"], samples["ticks"] = t, np.round(t * 1e4).astype(np.int64)
    samples["az"] = 9.81
    samples["pitch"] = np.radians(6.0)  # a pitch decay: the axis comes from the recording's metadata
    samples["pitch"][free], samples["q"][free] = simulate_decay(truth, t[free] - 2.0, np.radians(6.0))
    path = tmp_path / "decay.mcap"
    with RecordingWriter(path, {"axis": "pitch"}, {}) as writer:
        writer.write_samples(samples)
        writer.write_event("release", "released by hand", t_s=2.0)
    result = invoke(path, "--model", "b1,b2,c1,c3", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    for k, value in truth.items():
        assert out["coefficients"][k]["value"] == pytest.approx(value, rel=1e-3)
    assert out["runs"][0]["initial_angle_deg"] == pytest.approx(6.0, abs=0.01)
    assert out["axis"] == "pitch"


@pytest.mark.slow
def test_bootstrap_intervals_replace_the_jacobian_ones(tmp_path):
    result = invoke(
        write_held_tilt_csv(tmp_path / "a.csv"), "--model", "ittc-quadratic", "--bootstrap", "8", "--json"
    )
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["intervals"].startswith("moving-block bootstrap, 8 replicas")
    assert all(c["std"] > 0 for c in out["coefficients"].values())


@pytest.mark.slow
def test_repeats_give_intervals_from_the_spread_of_the_runs(tmp_path):
    files = [write_held_tilt_csv(tmp_path / f"{i}.csv", noise_deg=0.05, seed=i) for i in range(4)]
    result = invoke(*files, "--model", "ittc-quadratic", "--repeats", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["intervals"] == "repeat runs, 4 runs"
    for value, entry in zip((0.3, 0.4, 14.0), out["coefficients"].values(), strict=True):
        assert entry["ci95"][0] < value < entry["ci95"][1]
