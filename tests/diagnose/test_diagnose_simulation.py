"""tankdaq diagnose --simulation: a lab's simulation against its model test, what it misses, the gap.

Simulations are made here the way a code would make them, with the independent reference integrator
(``physics.decay.simulate_decay``, scipy DOP853), and written as CSV in another dialect than the
measurement (other column names, degrees, another rate and length).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from typer.testing import CliRunner

from support.figure_checks import assert_fit_to_hand_on, overlapping_texts
from support.rrd_checks import read_rrd
from tankdaq.cli import app
from tankdaq.config.hulls import load_hull
from tankdaq.diagnose.compare import SimulationComparison
from tankdaq.diagnose.sim_equation import best_damping_form
from tankdaq.diagnose.sim_report import figures, story, summary
from tankdaq.diagnose.simulation import SeriesColumns, SimulationRequest, resolve_simulation
from tankdaq.ident.free_decay import cut_free_decays
from tankdaq.ident.inputs import read_decays
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

runner = CliRunner()
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
KVLCC2 = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
)
KVLCC2_READ = ("--time-col", "time", "--angle-col", "phi", "--angle-unit", "rad")
#: How the simulations below are written: another time column, degrees, 50 Hz.
SIM_READ = ("--sim-time-col", "t_sim", "--sim-angle-col", "roll_deg", "--sim-angle-unit", "deg")
needs_kvlcc2 = pytest.mark.skipif(not KVLCC2.exists(), reason=f"KVLCC2 data not found at {KVLCC2}")


def invoke(*args: object):
    return runner.invoke(app, ["diagnose", *map(str, args)])


def write_sim_csv(path: Path, t: np.ndarray, angle_rad: np.ndarray, time_scale: float = 1.0) -> Path:
    """A simulation code's output: time in ``t_sim`` (times ``time_scale``), roll in degrees."""
    rows = np.column_stack([t * time_scale, np.degrees(angle_rad)])
    np.savetxt(path, rows, delimiter=",", header="t_sim,roll_deg", comments="", fmt="%.10g")
    return path


@pytest.fixture(scope="module")
def kvlcc2() -> tuple[list[DecayRun], OutputErrorFit]:
    """The measured free decay of run 21338 and the measurement's own fit the comparison makes."""
    if not KVLCC2.exists():
        pytest.skip(f"KVLCC2 data not found at {KVLCC2}")
    runs = cut_free_decays(read_decays(KVLCC2, "roll", "time", "phi", None, "rad"), None, None)
    return runs, best_damping_form(runs)


def simulate_from_release(fit: OutputErrorFit, coefficients: dict[str, float], duration_s: float) -> tuple:
    """The coefficients simulated at 50 Hz from the measured fit's release state."""
    t = np.arange(0.0, duration_s, 0.02)
    angle0, rate0 = fit.initial_states_[0]
    return t, simulate_decay(coefficients, t, angle0, rate0)[0]


@needs_kvlcc2
@pytest.mark.filterwarnings("ignore:RRD file has no footer")
@pytest.mark.slow
def test_potential_flow_simulation_misses_viscous_damping(tmp_path: Path, kvlcc2) -> None:
    """The 21338 restoring with a small linear (wave) damping only: found in damping, not stiffness;
    named in the damping family; added, the gap over the measured decay shrinks by >= 70 %."""
    runs, fit = kvlcc2
    c = fit.coefficients_
    potential = {
        "b1": 0.3 * c["b1"],
        "c1": c["c1"],
        "c3": c["c3"],
    }  # no amplitude-dependent (viscous) damping
    sim = write_sim_csv(tmp_path / "potential.csv", *simulate_from_release(fit, potential, 120.0))
    report, rrd = tmp_path / "report", tmp_path / "compare.rrd"
    result = invoke(
        KVLCC2, *KVLCC2_READ, "--simulation", sim, *SIM_READ, "--json", "--report", report, "--rrd", rrd
    )
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["simulation"]["kind"] == "series" and "simulated at 50 Hz" in out["simulation"]["notes"]
    assert set(out["simulation"]["equation"]["terms"]) == {"b1", "c1", "c3"}  # b2 ~ 0: dropped
    assert out["simulation"]["equation"]["coefficients"]["b1"] == pytest.approx(potential["b1"], rel=0.02)
    (match,) = out["matches"]
    assert match["measured"] == runs[0].name and match["simulated"] == "sim:potential"
    assert out["disagrees_in"] == ["damping"]
    assert abs(out["period"]["error"]) < 0.005 and out["period"]["agrees"]
    assert all(ratio < 0.5 for ratio in out["damping"]["ratio"]) and all(out["damping"]["disagrees"])
    assert out["damping"]["sentence"].startswith("simulation damping (B_eq) is ")
    first = out["steps"][0]
    assert "damping" in first["family"] and first["physics"]
    assert set(first["fixed"]) == {"b1", "c1", "c3"}  # the simulation's own terms held
    gap = out["gap"]
    assert gap["reduction"] >= 0.7 and gap["corrected_deg"] < 0.3 * gap["simulation_deg"]
    assert out["verdict"].startswith("missing: ")
    assert set(out["free_refit"]["coefficients"]) >= {"b1", "c1", "c3"}
    assert {t["term"] for t in out["correction"]["terms"]} == set().union(*(s["added"] for s in out["steps"]))
    for name in ("simulation.png", "damping.png"):
        assert (report / name).read_bytes()[:8] == PNG_MAGIC and f"]({name})" in (
            report / "simulation.md"
        ).read_text()
    scalars, texts = read_rrd(rrd)
    for series in (
        "angle/measured",
        "angle/simulation",
        "angle/corrected",
        "gap/simulation",
        "gap/corrected",
    ):
        assert len(scalars[f"/simulate/21338/{series}"]) == runs[0].t.size
    np.testing.assert_allclose(scalars["/simulate/21338/angle/measured"], np.degrees(runs[0].angle))
    gap_after = np.array(scalars["/simulate/21338/gap/corrected"])
    assert np.sqrt(np.mean(gap_after**2)) == pytest.approx(gap["corrected_deg"], rel=1e-6)
    assert out["period"]["sentence"] in texts and texts[-1] == out["verdict"]


@needs_kvlcc2
@pytest.mark.slow
def test_a_simulation_with_the_wrong_gm_is_corrected_in_its_stiffness(tmp_path: Path, kvlcc2) -> None:
    """The 21338 fit with half its linear restoring (a GM halved: the period 41 % long) is corrected in
    its stiffness alone. Before: the stiffness refit started from the simulation's c1 and stopped in a
    local minimum (the phase wrapped over 143 cycles), so linear damping was named first (b1 up from
    0.019 to 1.7 1/s, the simulation damped out) and kept in the correction after the stiffness step
    had refitted it back; on a shorter decay the measured roll left in the residual was named
    "coupling with an unmeasured motion", then a GZ curve in place of c1."""
    _, fit = kvlcc2
    c = dict(fit.coefficients_)
    soft = {**c, "c1": 0.5 * c["c1"]}
    sim = write_sim_csv(tmp_path / "soft.csv", *simulate_from_release(fit, soft, 120.0))
    result = invoke(KVLCC2, *KVLCC2_READ, "--simulation", sim, *SIM_READ, "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert "stiffness" in out["disagrees_in"] and not out["period"]["agrees"]
    first = out["steps"][0]
    assert first["key"] == "restoring.linear" and set(first["added"]) == {"c1"}
    assert first["added"]["c1"] == pytest.approx(0.5 * c["c1"], rel=0.02)
    assert not [s for s in out["steps"] if s["key"] in ("coupling.unmeasured", "restoring.sine")]
    assert [t["term"] for t in out["correction"]["terms"]] == ["c1"]
    assert out["gap"]["reduction"] >= 0.9


@pytest.mark.slow
def test_a_simulation_far_off_in_period_is_not_an_unmeasured_motion(tmp_path: Path) -> None:
    """Measured: 20 s of b1 0.3, b2 0.05, c1 14 with sensor noise. The simulation has c1 4 and no b2
    (the period 87 % long). Its residual holds the measured roll at 1.87 times the simulation's own
    frequency, which is no harmonic of it: that was taken for another motion (a ringing term fitted at
    the measured frequency), and a GZ curve s1 sin(x) put in place of the simulation's c1 x. It is the
    stiffness (c1 + 10), then the quadratic damping."""
    truth, simulated = {"b1": 0.3, "b2": 0.05, "c1": 14.0}, {"b1": 0.3, "c1": 4.0}
    t = np.arange(0.0, 20.0, 0.01)
    angle = simulate_decay(truth, t, math.radians(8.0))[0] + np.random.default_rng(3).normal(0, 2e-4, t.size)
    measured = tmp_path / "measured.csv"
    np.savetxt(measured, np.column_stack([t, np.degrees(angle)]), delimiter=",", header="time_s,angle_deg",
               comments="", fmt="%.10g")  # fmt: skip
    t_sim = np.arange(0.0, 20.0, 0.02)
    sim = write_sim_csv(tmp_path / "soft.csv", t_sim, simulate_decay(simulated, t_sim, math.radians(8.0))[0])
    result = invoke(measured, "--simulation", sim, *SIM_READ, "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    keys = [step["key"] for step in out["steps"]]
    assert keys[0] == "restoring.linear" and not {"coupling.unmeasured", "restoring.sine"} & set(keys)
    added = {term["term"]: term["per_unit_inertia"] for term in out["correction"]["terms"]}
    assert added["c1"] == pytest.approx(10.0, rel=0.02) and added["b2"] == pytest.approx(0.05, rel=0.1)
    assert out["gap"]["reduction"] >= 0.9


@needs_kvlcc2
@pytest.mark.slow
def test_a_right_simulation_names_nothing(tmp_path: Path, kvlcc2) -> None:
    """Control: the measured fit itself, simulated and with sensor-class noise, is not corrected."""
    runs, fit = kvlcc2
    t, angle = simulate_from_release(fit, fit.coefficients_, 100.0)
    angle = angle + np.random.default_rng(3).normal(0.0, 5e-4, angle.size)
    path = write_sim_csv(tmp_path / "right.csv", t, angle)
    request = SimulationRequest(tuple(runs), columns=SeriesColumns("t_sim", "roll_deg", None, "deg"))
    comparison = SimulationComparison(resolve_simulation([str(path)], request)).fit(runs)
    assert comparison.steps_ == [] and comparison.disagrees_in_ == ()
    assert comparison.verdict_.startswith("nothing missing")
    assert comparison.correction_.terms == []
    lines = story(comparison)
    assert lines[-1] == comparison.verdict_ and not any(line.startswith("added ") for line in lines)
    assert_no_overlap(figures(comparison))


def assert_no_overlap(figs: dict[str, Figure]) -> None:
    """No text over text or cut off, no legend on a panel (``figure_checks``)."""
    for name, fig in figs.items():
        assert_fit_to_hand_on(fig, name)


def write_hull(path: Path, coefficients: dict[str, float], scale: float | None = 10.0) -> Path:
    """The shipped SWATH's particulars with the given [simulation] roll coefficients at T."""
    lines = [
        'name = "swath-altered"',
        "[dimensions]",
        "displacement_kg = 30.0",
        *(["[particulars]", f"scale_factor = {scale}"] if scale else []),
        "[axes.roll]",
        "gm_m = 0.08",
        "radius_of_gyration_m = 0.2",
        '[simulation.roll.drafts."T"]',
        *(f"{k} = {v!r}" for k, v in coefficients.items()),
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_swath_decays(folder: Path, angles_deg: tuple[float, ...] = (12.0, 8.0, 4.0)) -> list[Path]:
    """'Measured' roll decays of the shipped SWATH at T (its [simulation] truth, MTi-class noise), CSV."""
    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    rng = np.random.default_rng(11)
    t = np.arange(0.0, 12.0, 0.01)
    paths = []
    for angle in angles_deg:
        x, v = simulate_decay(truth, t, math.radians(angle))
        x, v = x + rng.normal(0, 0.001, t.size), v + rng.normal(0, 0.002, t.size)
        path = folder / f"swath_{angle:g}deg.csv"
        columns = np.column_stack([t, np.degrees(x), np.degrees(v)])
        np.savetxt(
            path, columns, delimiter=",", header="time_s,angle_deg,rate_deg_s", comments="", fmt="%.9g"
        )
        paths.append(path)
    return paths


@pytest.mark.slow
def test_hull_simulation_without_its_cubic_damping(tmp_path: Path) -> None:
    """--simulation hull: a hull file whose [simulation] lacks the cubic damping the decays have."""
    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    altered = {k: v for k, v in truth.items() if k != "b3"}
    hull = write_hull(tmp_path / "swath-altered.toml", altered, scale=10.0)
    decays = write_swath_decays(tmp_path)
    result = invoke(*decays, "--simulation", "hull", "--hull", hull, "--draft", "T", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["simulation"]["kind"] == "model" and out["simulation"]["name"].startswith("hull swath-altered")
    assert out["matches"] is None and out["disagrees_in"] == ["damping"]
    assert out["steps"][0]["family"] == "amplitude-dependent damping"
    assert out["gap"]["reduction"] >= 0.7
    correction = out["correction"]
    stiffness = out["measured_model"]["coefficients"]["c1"]
    inertia = 30.0 * 9.81 * 0.08 / stiffness
    assert correction["total_inertia_kg_m2"] == pytest.approx(inertia)
    assert correction["added_inertia_fraction"] == pytest.approx(inertia / (30.0 * 0.2**2) - 1)
    for term in correction["terms"]:
        assert term["model_scale"] == pytest.approx(term["per_unit_inertia"] * inertia)
        if term["term"] == "fc":  # the rig's friction has no full scale
            assert term["full_scale"] is None
        else:
            assert term["full_scale"] == pytest.approx(term["model_scale"] * 10.0 ** term["froude_exponent"])
    exponents = {t["term"]: t["froude_exponent"] for t in correction["terms"]}
    assert (
        exponents.get("b2", 5.0) == 5.0
        and exponents.get("b3", 5.5) == 5.5
        and exponents.get("b1", 4.5) == 4.5
    )


@pytest.mark.slow
def test_report_figures_of_a_hull_comparison_do_not_overlap(tmp_path: Path) -> None:
    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    hull = load_hull(str(write_hull(tmp_path / "h.toml", {**truth, "b1": 0.5 * truth["b1"]}, scale=None)))
    runs = [run for path in write_swath_decays(tmp_path) for run in read_decays(path)]
    sim = resolve_simulation(["hull"], SimulationRequest(tuple(runs), hull=hull))
    comparison = SimulationComparison(sim, max_steps=1, hull=hull).fit(runs)
    assert comparison.correction_.scale_factor is None and comparison.correction_.total_inertia_kg_m2
    assert any("model scale only" in note for note in comparison.correction_.notes)
    assert_no_overlap(figures(comparison))


def test_the_overlap_check_sees_text_drawn_over_text() -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = Figure(figsize=(3, 2))
    FigureCanvasAgg(fig)
    fig.text(0.2, 0.5, "a long label here")
    fig.text(0.25, 0.5, "another one")
    fig.text(0.2, 0.1, "far away")
    assert overlapping_texts(fig) == [("a long label here", "another one")]


def test_fixed_coefficients_hold_only_the_terms_named() -> None:
    """A simulation's own terms fixed, the added ones fitted (OutputErrorFit's fixed_coefficients)."""
    t = np.arange(0.0, 20.0, 0.01)
    truth = {"b1": 0.1, "b2": 0.3, "c1": 4.0}
    angle, rate = simulate_decay(truth, t, 0.2)
    run = DecayRun(t, angle + np.random.default_rng(2).normal(0, 1e-4, t.size), rate)
    fit = OutputErrorFit(("b1", "b2", "c1"), compute_diagnostics=False).fit(
        [run], fixed_coefficients={"c1": 4.0}
    )
    assert fit.coefficients_["c1"] == 4.0 and fit.std_["c1"] == 0.0
    assert fit.coefficients_["b1"] == pytest.approx(0.1, rel=0.05)
    assert fit.coefficients_["b2"] == pytest.approx(0.3, rel=0.05)


@pytest.fixture
def swath_decays(tmp_path: Path) -> list[Path]:
    return write_swath_decays(tmp_path)


def sim_of_swath(
    folder: Path, angle_deg: float = 12.0, time_scale: float = 1.0, unit_deg: bool = True
) -> Path:
    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    t = np.arange(0.0, 8.0, 0.005)  # 200 Hz, shorter than the measured
    angle = simulate_decay(truth, t, math.radians(angle_deg))[0]
    return write_sim_csv(folder / "sim.csv", t, angle if unit_deg else np.radians(angle), time_scale)


@pytest.mark.parametrize(
    ("make_sim", "extra", "message"),
    [
        (
            lambda d: sim_of_swath(d),
            ("--sim-angle-unit", "rad"),
            "the data look like deg (12.1 deg): use --sim-angle-unit deg",
        ),
        (lambda d: sim_of_swath(d, angle_deg=30.0), (), "no simulated run starts near a measured one"),
        (lambda d: sim_of_swath(d), ("--sim-angle-col", "pitch"), "no angle column"),
        (lambda d: sim_of_swath(d), ("--sim-time-col", "t"), "(choose with --sim-time-col)"),
        (lambda d: sim_of_swath(d), ("--baseline", "b1,c1"), "--baseline does not apply"),
        (lambda d: d / "missing.csv", (), "no such file"),
        (lambda d: "ikeda", (), "--simulation ikeda needs --hull"),
        (lambda d: "hull", (), "needs --hull"),
        (lambda d: growing_sim(d), (), "simulation sim.csv grows: its swing rises from"),
    ],
)
@pytest.mark.slow
def test_bad_simulations_are_one_line_and_exit_2(
    tmp_path: Path, swath_decays, make_sim, extra, message
) -> None:
    sim = make_sim(tmp_path)
    read = () if isinstance(sim, str) else ("--sim-time-col", "t_sim", "--sim-angle-col", "roll_deg")
    result = invoke(*swath_decays, "--simulation", sim, *read, *extra)
    assert result.exit_code == 2, result.output
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], result.stderr
    assert "Traceback" not in result.output


def growing_sim(folder: Path) -> Path:
    """An unstable simulation (a negative linear damping): its swing grows from 12 deg (issue 37: it was
    read as "5 decays found" and compared)."""
    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    t = np.arange(0.0, 8.0, 0.005)
    angle = simulate_decay({**truth, "b1": -0.3, "b3": 0.0}, t, math.radians(12.0))[0]
    return write_sim_csv(folder / "sim.csv", t, angle)


@pytest.mark.parametrize("source", ["ikeda", "hull"])
def test_decays_of_another_hull_are_refused_naming_both(tmp_path: Path, swath_decays, source: str) -> None:
    """SWATH decays (named so: hull, draft, axis, angle) against kvlcc2's prediction or a hull file of
    another name: one line naming both hulls, no comparison and no full-scale correction (issue 37: a
    correction of +8.5e12 N m s^3 for the wrong ship)."""
    named = []
    for path in swath_decays:
        named.append(path.rename(path.with_name(f"swath_T_roll_{path.name.split('_')[1]}")))
    other = (
        "kvlcc2" if source == "ikeda" else str(write_hull(tmp_path / "other.toml", {"b1": 0.3, "c1": 14.0}))
    )
    result = invoke(*named, "--simulation", source, "--hull", other)
    assert result.exit_code == 2, result.output
    name = "kvlcc2" if source == "ikeda" else "swath-altered"
    assert result.stderr.strip() == (
        f"error: the decays were recorded on hull swath, not {name} (--hull): a simulation of {name} says "
        "nothing of them; give --hull swath"
    )
    assert "correction" not in result.stdout


def test_a_hull_without_simulation_coefficients_is_one_line(tmp_path: Path, swath_decays) -> None:
    hull = tmp_path / "bare.toml"
    hull.write_text('name = "bare"\n[dimensions]\ndisplacement_kg = 30.0\n[axes.roll]\ngm_m = 0.08\n')
    result = invoke(*swath_decays, "--simulation", "hull", "--hull", hull)
    assert result.exit_code == 2 and "has no simulation coefficients for roll" in result.stderr


def write_sim_mcap(path: Path, angle_deg: float) -> Path:
    """The SWATH's own [simulation] decay from ``angle_deg`` as a tankdaq recording (held, released)."""
    from tankdaq.samples import SAMPLE_DTYPE
    from tankdaq.store.writer import RecordingWriter

    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    t = np.arange(0.0, 10.0, 0.01)
    x, v = simulate_decay(truth, t, math.radians(angle_deg))
    held = np.arange(-100, 0) / 100.0
    t_all = np.concatenate([held, t]) + 5.0
    samples = np.zeros(t_all.size, dtype=SAMPLE_DTYPE)
    samples["t"], samples["ticks"] = t_all, np.round(t_all * 1e4).astype(np.int64)
    samples["roll"] = np.concatenate([np.full(held.size, x[0]), x])
    samples["p"] = np.concatenate([np.zeros(held.size), v])
    samples["az"] = 9.81
    with RecordingWriter(path, {"axis": "roll"}, {}) as writer:
        writer.write_samples(samples)
        writer.write_event("release", "released by the simulation", t_s=5.0)
    return path


@pytest.mark.slow
def test_mcap_simulations_are_matched_by_initial_angle(tmp_path: Path, swath_decays) -> None:
    """Two simulated recordings (12 and 8 deg) against three measured decays: the 4-deg one has no match
    (said, not compared); the simulation is the truth, so nothing is missing."""
    sims = [write_sim_mcap(tmp_path / f"sim_{a:g}.mcap", a) for a in (8.0, 12.0)]
    result = invoke(*swath_decays, "--simulation", sims[0], "--simulation", sims[1], "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    pairs = {(m["measured"], m["simulated"]) for m in out["matches"]}
    assert pairs == {("swath_12deg", "sim:sim_12"), ("swath_8deg", "sim:sim_8")}
    assert out["runs"] == ["swath_12deg", "swath_8deg"]
    assert out["warnings"] == [
        "measured run swath_4deg has no simulated run near its initial angle: not compared"
    ]
    assert out["steps"] == [] and out["verdict"].startswith("nothing missing")
    assert out["simulation"]["equation"]["coefficients"]["c1"] == pytest.approx(14.2185, rel=0.01)


def test_short_run_labels() -> None:
    from tankdaq.viz.plots import short_labels

    assert short_labels(["model_test_21338"]) == ["21338"]
    assert short_labels(["model_test_21338#1", "model_test_21338#2"]) == ["21338_1", "21338_2"]
    assert short_labels(["swath_12deg", "swath_8deg"]) == ["12deg", "8deg"]
    assert short_labels(["x" * 40, "y" * 40]) == ["run1", "run2"]  # nothing short tells them apart


@pytest.mark.slow
def test_an_ikeda_prediction_of_kvlcc2_is_compared_in_its_own_components(kvlcc2) -> None:
    """The shipped KVLCC2's simplified Ikeda prediction against run 21338: damping, not stiffness, differs,
    the inputs outside the method's range are named, and the prediction says which of its components
    would have to change, and by how much, to meet the measurement."""
    from tankdaq.config.hulls import load_hull
    from tankdaq.diagnose.compare import SimulationComparison
    from tankdaq.diagnose.simulation import SimulationRequest, resolve_simulation

    runs, _ = kvlcc2
    hull = load_hull("kvlcc2")
    simulation = resolve_simulation(["ikeda"], SimulationRequest(tuple(runs), "roll", hull, 1.0))
    assert simulation.kind == "prediction" and set(simulation.coefficients) == {"b1", "b2", "c1"}
    assert any("CMID" in note for note in simulation.notes)  # 0.9954 is above the paper's 0.99
    comparison = SimulationComparison(simulation, max_steps=1, hull=hull).fit(runs)
    assert comparison.disagrees_in_ == ("damping",)
    linear, quadratic = comparison.component_changes_
    assert linear.startswith("b1:") and "friction" in linear and "wave" in linear
    assert quadratic.startswith("b2:") and "eddy" in quadratic and "bilge keel" in quadratic
    # B_eq measured below the prediction (the kvlcc2 hull's docs): both parts would have to shrink
    factors = [float(line.split("change x")[1].split()[0]) for line in (linear, quadratic)]
    assert all(0.0 < factor < 1.0 for factor in factors), factors
    # B̂44 beside B_eq/I, by hand from the parameters file's columns (model scale: lengths / lambda)
    with (KVLCC2.parent / "model_test_parameters.csv").open() as f:
        row = next(r for r in csv.DictReader(f) if r["id"] == "21338")
    lam, rho, g = float(row["scale_factor"]), float(row["rho"]), float(row["g"])
    mass, beam, gm = rho * float(row["Volume"]) / lam**3, float(row["beam"]) / lam, float(row["gm"]) / lam
    reference = comparison.reference_.coefficients_
    inertia = mass * g * gm / (reference["c1"] + reference.get("s1", 0.0))
    damping = summary(comparison)["damping"]
    for side in ("measured", "simulation", "corrected"):
        hand = [b * inertia * math.sqrt(beam / (2 * g)) / (mass * beam**2) for b in damping[side]["b_eq_1_s"]]
        assert damping[side]["b44_hat"] == pytest.approx(hand, rel=1e-6)
    assert_no_overlap(figures(comparison))  # damping.png with B̂44's axis


def test_a_simulation_with_time_in_milliseconds_is_read_as_such(tmp_path: Path, swath_decays) -> None:
    """Another code's time column in ms is found from the data (a decay's period), said, and compared."""
    sim = sim_of_swath(tmp_path, time_scale=1000.0)
    result = invoke(
        *swath_decays, "--simulation", sim, "--sim-time-col", "t_sim", "--sim-angle-col", "roll_deg"
    )
    assert result.exit_code == 0, result.output
    assert any("simulation: " in line and "time unit: ms" in line for line in result.stdout.splitlines())
    assert "period agrees to 0." in result.stdout and "nothing missing" in result.stdout, result.stdout
