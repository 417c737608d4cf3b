"""tankdaq diagnose end to end on CSV files, the Markdown report, the rerun log, and one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from typer.testing import CliRunner

from support.rrd_checks import read_rrd
from tankdaq.cli import app
from tankdaq.diagnose.report import log_to_rerun, story
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.diagnose.workflow import Diagnoser

runner = CliRunner()
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def write_csvs(folder: Path, effects: tuple[str, ...], seed: int) -> list[Path]:
    """One CSV per decay in the format tankdaq identify reads (degrees, extra channels as columns)."""
    data = make_decay_set(effects, seed=seed)
    paths = []
    for run in data.runs:
        columns = {"time_s": run.t, "angle_deg": np.degrees(run.angle), "rate_deg_s": np.degrees(run.rate)}
        columns |= run.channels
        path = folder / f"{run.name}.csv"
        rows = np.column_stack(list(columns.values()))
        np.savetxt(path, rows, delimiter=",", header=",".join(columns), comments="", fmt="%.9g")
        paths.append(path)
    return paths


def invoke(*args: object):
    return runner.invoke(app, ["diagnose", *map(str, args)])


@pytest.mark.slow
def test_json_tells_the_story_of_a_hidden_heave_coupling(tmp_path: Path) -> None:
    result = invoke(*write_csvs(tmp_path, ("coupling.heave",), seed=21), "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["baseline"]["terms"] == ["b1", "c1"]
    for key in ("rms_angle_deg", "nrmse", "ljung_box_p"):
        assert key in out["baseline"] and key in out["final"]
    first = out["steps"][0]
    assert first["family"] == "coupled motion" and first["terms"].startswith("k*z(t)")
    assert set(first["coefficients"]) == {"k_heave_m"}
    assert first["delta_bic"] < -10 and first["rms_after_deg"] < first["rms_before_deg"]
    assert out["baseline"]["ljung_box_p"] < 0.01 < first["ljung_box_p_after"]
    before, after = first["held_out_rms_noise_units"]
    assert after < before and after < 1.3
    assert out["final"]["terms"] == ["b1", "c1", "k_heave_m"]
    assert 0 < out["gap_reduction"] < 1 and out["gap_reduction_all_outputs"] > 0.5
    assert "coupling with heave" in out["verdict"]
    assert [cut["run"] for cut in out["cuts"]] == out["runs"]  # where each free decay ends, and why
    assert all(cut["line"].startswith(f"{cut['run']}: free decay") for cut in out["cuts"])


def split_cut_lines(lines: list[str]) -> tuple[list[str], list[str]]:
    """The story's leading ``cut:`` lines (one per run), and the rest."""
    cuts = [line for line in lines if line.startswith("cut: ")]
    return cuts, lines[len(cuts) :]


@pytest.mark.slow
def test_text_and_report(tmp_path: Path) -> None:
    report = tmp_path / "report"
    result = invoke(*write_csvs(tmp_path, ("damping.quadratic",), seed=22), "--report", report)
    assert result.exit_code == 0, result.output
    cuts, lines = split_cut_lines(result.stdout.strip().splitlines())
    assert cuts and all(": free decay " in cut for cut in cuts)  # one line per run: where its free decay ends
    assert lines[0].startswith("baseline b1,c1: RMS") and "not white" in lines[0]
    assert any(line.startswith("added quadratic damping (amplitude-dependent damping)") for line in lines)
    assert lines[-1].startswith("missing: quadratic damping")
    text = (report / "diagnose.md").read_text()
    for name in ("models.png", "residuals.png", "spectrum.png"):
        assert f"]({name})" in text
        assert (report / name).read_bytes()[:8] == PNG_MAGIC
    assert "| 1 | quadratic damping | amplitude-dependent damping |" in text


def test_max_steps_zero_only_fits_the_baseline(tmp_path: Path) -> None:
    result = invoke(*write_csvs(tmp_path, ("sensor.offset",), seed=23), "--max-steps", "0", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["steps"] == [] and out["final"]["terms"] == out["baseline"]["terms"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.csv"], "no such file"),
        (["{csv}", "--baseline", "b1,zz"], "unknown model term"),
        (["{csv}", "--baseline", "b1,c1,fc"], "friction and coupling"),
        (["{csv}", "--axis", "yaw"], "axis 'yaw'"),
        (["{csv}", "--max-steps", "-1"], "max-steps"),
        (["{csv}", "--angle-col", "phi"], "no angle column"),
    ],
)
@pytest.mark.slow
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, args: list[str], message: str) -> None:
    csv = write_csvs(tmp_path, (), seed=24)[0]
    result = invoke(*[a.format(csv=csv) for a in args])
    assert result.exit_code == 2, result.output
    error_lines = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(error_lines) == 1 and message in error_lines[0]
    assert "Traceback" not in result.output


@pytest.mark.filterwarnings("ignore:RRD file has no footer")
@pytest.mark.slow
def test_the_story_goes_to_rerun(tmp_path: Path) -> None:
    data = make_decay_set(("restoring.cubic",), seed=25)
    diagnoser = Diagnoser().fit(data.runs)
    path = tmp_path / "diagnose.rrd"
    stream = rr.RecordingStream("tankdaq")
    stream.save(str(path))
    log_to_rerun(diagnoser, stream)
    stream.flush()
    stream.disconnect()
    assert_rrd_tells(path, data.runs, data.noise_angle_rad, story(diagnoser))


@pytest.mark.filterwarnings("ignore:RRD file has no footer")
@pytest.mark.slow
def test_cli_writes_the_rrd(tmp_path: Path) -> None:
    from tankdaq.ident.inputs import read_decays

    csvs = write_csvs(tmp_path, ("sensor.offset",), seed=27)
    result = invoke(*csvs, "--rrd", tmp_path / "story.rrd")
    assert result.exit_code == 0, result.output
    runs = [run for path in csvs for run in read_decays(path)]  # as the command read them (cut at release)
    noise = make_decay_set(("sensor.offset",), seed=27).noise_angle_rad
    assert_rrd_tells(tmp_path / "story.rrd", runs, noise, result.stdout.strip().splitlines())
    missing_folder = invoke(*csvs, "--rrd", tmp_path / "nowhere" / "story.rrd")
    assert missing_folder.exit_code == 2 and "does not exist" in missing_folder.stderr


def assert_rrd_tells(path: Path, runs: list, noise_rad: float, lines: list[str]) -> None:
    """The .rrd holds per run the five series over the whole record and the story, line for line."""
    scalars, texts = read_rrd(path)
    for run in runs:
        for series in (
            "angle/measured",
            "angle/baseline",
            "angle/final",
            "residual/baseline",
            "residual/final",
        ):
            assert len(scalars[f"/diagnose/{run.name}/{series}"]) == run.t.size
        np.testing.assert_allclose(scalars[f"/diagnose/{run.name}/angle/measured"], np.degrees(run.angle))
        final_residual = np.array(scalars[f"/diagnose/{run.name}/residual/final"])
        assert np.sqrt(np.mean(final_residual**2)) < 1.3 * np.degrees(noise_rad)
    assert texts == lines


@pytest.mark.slow
def test_mcap_recordings_are_diagnosed(tmp_path: Path) -> None:
    from tankdaq.samples import SAMPLE_DTYPE
    from tankdaq.store.writer import RecordingWriter

    data = make_decay_set(("damping.quadratic",), seed=26)
    rng = np.random.default_rng(26)
    paths = []
    for run in data.runs:
        held = np.arange(-100, 0) / 100.0  # one second held at the release angle before it
        t = np.concatenate([held, run.t]) + 5.0
        samples = np.zeros(t.size, dtype=SAMPLE_DTYPE)
        samples["t"], samples["ticks"] = t, np.round(t * 1e4).astype(np.int64)
        samples["roll"] = np.concatenate([np.full(held.size, run.angle[0]), run.angle])
        samples["p"] = np.concatenate([np.zeros(held.size), run.rate])
        samples["pitch"] = rng.normal(0, 0.001, t.size)  # the other axis and gravity: noise only
        samples["az"] = 9.81 + rng.normal(0, 0.01, t.size)
        path = tmp_path / f"{run.name}.mcap"
        with RecordingWriter(path, {"axis": "roll"}, {}) as writer:
            writer.write_samples(samples)
            writer.write_event("release", "released by hand", t_s=5.0)
        paths.append(path)
    result = invoke(*paths, "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert [s["family"] for s in out["steps"]] == ["amplitude-dependent damping"]
    assert out["final"]["coefficients"]["b2"] == pytest.approx(data.truth["b2"], rel=0.2)
