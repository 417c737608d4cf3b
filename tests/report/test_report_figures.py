"""Every report figure is fit to hand on: rendered from small inputs, no text overlaps or is cut off, no
legend sits on a panel, decays run in time since release, runs have short labels, the spectrum is in Hz
and B̂44 stands beside B_eq/I where the hull gives it (issue 23 item 4)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from support.figure_checks import assert_fit_to_hand_on, clipped_texts, layout_problems, legends_on_axes
from tankdaq.auv.model import StateRecord
from tankdaq.auv.validate import ValidationResult
from tankdaq.campaign.groups import (
    GroupResult,
    find_campaign_hulls,
    find_recordings,
    group_runs,
    identify_groups,
    markdown_table,
    read_campaign_runs,
)
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.config.hulls import load_hull
from tankdaq.diagnose.residuals import residual_spectrum
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.ident.interval_labels import FIT_STD
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun
from tankdaq.viz import campaign_report, diagnose_view, plots
from tankdaq.viz.auv_view import validation_figure
from tankdaq.viz.plots import decay_fit_figure, series_figure

LONG_NAMES = [f"swath_1.1T_roll_{a}deg_20261121-1430{k}5_run0{k}" for k, a in ((1, 12), (2, 8), (3, 4))]
DEVICE_T0_S = 22568.0  # a device clock far from zero: the figures must not show it


@dataclasses.dataclass
class Prediction:
    """A run as a model sees it (``diagnose_view.PredictedRun``)."""

    name: str
    t: np.ndarray
    angle: np.ndarray
    residual_angle: np.ndarray


def predictions(scale: float = 1.0) -> list[Prediction]:
    t = DEVICE_T0_S + np.arange(0.0, 12.0, 0.01)
    out = []
    for name, angle_deg in zip(LONG_NAMES, (12.0, 8.0, 4.0), strict=True):
        x, _ = simulate_decay({"b1": 0.3, "b2": 0.4, "c1": 14.0}, t - t[0], math.radians(angle_deg))
        residual = scale * 0.002 * np.sin(2 * 3.74 * (t - t[0])) * np.exp(-0.1 * (t - t[0]))
        out.append(Prediction(name, t, x, residual))
    return out


@pytest.mark.slow
def test_the_checks_see_clipping_and_a_legend_on_data() -> None:
    fig = Figure(figsize=(4, 3))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.25, 0.2, 0.5, 0.7))
    ax.plot([0, 1], [0, 1], label="data")
    ax.legend(loc="center")
    fig.text(0.9, 0.5, "runs off the right edge")
    assert legends_on_axes(fig) == ["data"]
    assert clipped_texts(fig) == ["runs off the right edge"]
    assert layout_problems(fig)["overlapping"] == []


@pytest.mark.slow
def test_decay_figure_in_time_since_release_with_its_legend_beside() -> None:
    (run, *_) = predictions()
    fig = decay_fit_figure(run.t - run.t[0], run.angle + run.residual_angle, run.angle, title=LONG_NAMES[0])
    top, bottom = fig.axes
    assert bottom.get_xlabel() == "time since release (s)"
    assert top.get_lines()[0].get_xdata()[0] == 0.0
    assert_fit_to_hand_on(fig, "decay")
    x = np.array([2.0, 4.0, 8.0])
    two = series_figure(
        x, {"T": (x, None), "1.1T": (2 * x, 0.1 * x)}, xlabel="a (deg)", ylabel="B (1/s)", interval=FIT_STD
    )
    assert_fit_to_hand_on(two, "series")


def test_run_labels_are_condition_and_run_number() -> None:
    runs = [
        DecayRun(np.arange(3.0), np.zeros(3), name=Path(n).stem, meta={"file": f"/lab/{n}.mcap"})
        for n in LONG_NAMES
    ]
    assert plots.run_labels(runs) == [
        "swath 1.1T roll #1",
        "swath 1.1T roll #2",
        "swath 1.1T roll #3",
    ]
    # names that say no condition: the shortest unique tails, never the whole names
    plain = [DecayRun(np.arange(3.0), np.zeros(3), name=n) for n in ("model_test_21338", "model_test_21340")]
    assert plots.run_labels(plain) == ["21338", "21340"]


@pytest.mark.slow
def test_diagnose_figures_show_time_since_release_short_labels_and_no_overlap() -> None:
    baseline, final = predictions(), predictions(0.1)
    labels = ["swath 1.1T roll #1", "swath 1.1T roll #2", "swath 1.1T roll #3"]
    models = diagnose_view.models_figure(baseline, final, labels)
    residuals = diagnose_view.residuals_figure(baseline, final, labels)
    for name, fig in (("models", models), ("residuals", residuals)):
        assert [ax.get_title(loc="left") for ax in fig.axes] == labels, name
        assert fig.axes[-1].get_xlabel() == "time since release (s)"
        assert all(ax.get_lines()[0].get_xdata()[0] == 0.0 for ax in fig.axes), name
        assert_fit_to_hand_on(fig, name)
    # without labels the panels are named by the names' short tails, not the whole file names
    unnamed = diagnose_view.models_figure(baseline, final)
    assert all(len(ax.get_title(loc="left")) <= plots.LABEL_CHARS for ax in unnamed.axes)
    assert_fit_to_hand_on(unnamed, "models without labels")


@pytest.mark.slow
def test_spectrum_is_asd_in_hz_against_hz_with_a_fine_grid() -> None:
    rate_hz, omega0 = 100.0, math.sqrt(14.0)
    residuals = [p.residual_angle for p in predictions()]
    coarse = residual_spectrum(residuals, rate_hz, omega0)
    fine = residual_spectrum(residuals, rate_hz, omega0, padding=8)
    assert fine.omega_rad_s.size == 8 * (coarse.omega_rad_s.size - 1) + 1  # zero padding: 8 x the bins
    assert fine.location == coarse.location  # where the peak is said to sit does not change
    fig = diagnose_view.spectrum_figure(coarse, fine, omega0)
    (ax,) = fig.axes
    assert ax.get_xlabel().startswith("frequency (Hz)") and "deg/√Hz" in ax.get_ylabel()
    baseline_line, final_line = ax.get_lines()[:2]
    np.testing.assert_allclose(baseline_line.get_xdata(), coarse.omega_rad_s / (2 * np.pi))
    np.testing.assert_allclose(final_line.get_xdata(), fine.omega_rad_s / (2 * np.pi))
    np.testing.assert_allclose(final_line.get_ydata(), np.degrees(np.sqrt(fine.psd)))
    assert ax.get_xlim()[1] == pytest.approx(6 * omega0 / (2 * np.pi))
    marks = [line.get_xdata()[0] for line in ax.get_lines()[2:]]
    assert marks == pytest.approx([k * omega0 / (2 * np.pi) for k in (1, 2, 3)])
    assert_fit_to_hand_on(fig, "spectrum")


@pytest.mark.slow
def test_simulation_and_damping_figures_carry_b44_hat_beside_b_eq() -> None:
    sim, fixed = predictions(), predictions(0.1)
    labels = plots.run_labels(
        [DecayRun(p.t, p.angle, name=p.name, meta={"file": p.name + ".mcap"}) for p in sim]
    )
    assert_fit_to_hand_on(diagnose_view.simulation_figure(sim, fixed, labels, (1.234, 0.0567)), "simulation")
    long = [f"catamaran-2026-long-lab-model-name 1.1T roll #{k}" for k in (1, 2, 3)]  # a lab's hull name
    drawn = diagnose_view.simulation_figure(sim, fixed, long, (1.234, 0.0567))
    assert_fit_to_hand_on(drawn, "simulation with long labels")
    assert [ax.get_title(loc="left") for ax in drawn.axes[::2]] == long
    amplitudes = [1.0, 4.0, 8.0, 12.0]
    value = np.array([0.2, 0.3, 0.4, 0.5])
    bands = {
        name: (k * value, 0.01 * value)
        for name, k in (("measured", 1.0), ("simulation", 0.5), ("corrected", 0.95))
    }
    peaks = np.radians(np.array([10.0, 7.0, 5.0]))
    decrements = {name: (peaks, 0.1 * peaks) for name in bands}
    plain = diagnose_view.damping_figure(amplitudes, bands, decrements)
    hat = diagnose_view.damping_figure(amplitudes, bands, decrements, b44_hat_per_b_eq=0.004)
    assert_fit_to_hand_on(plain, "damping")
    assert_fit_to_hand_on(hat, "damping with B̂44")
    left = hat.axes[0]
    (secondary,) = [child for child in left.child_axes]
    assert "B̂44" in secondary.get_ylabel() and left.get_ylabel() == "B_eq / I (1/s)"
    low, high = left.get_ylim()
    assert secondary.get_ylim() == pytest.approx((0.004 * low, 0.004 * high))


@pytest.fixture(scope="module")
def campaign_results(tmp_path_factory: pytest.TempPathFactory) -> list[GroupResult]:
    """Two hulls (swath gives beam and displacement: B̂44), two drafts, one angle, fitted; one hull
    renamed as a lab might name it, so the legends hold a long name."""
    folder = tmp_path_factory.mktemp("figures_campaign")
    write_simulated_campaign(folder, ["swath", "catamaran"], "roll", [1.0, 1.1], [8.0], "csv", seed=5)
    runs = [run for path in find_recordings([folder]) for run in read_campaign_runs(path)]
    groups = group_runs(runs)
    results = identify_groups(groups, model="b1,b2,c1", hulls=find_campaign_hulls(k.hull for k in groups))
    long_name = "catamaran-2026-long-lab-model-name"
    return [
        dataclasses.replace(r, key=dataclasses.replace(r.key, hull=long_name))
        if r.key.hull == "catamaran"
        else r
        for r in results
    ]


@pytest.mark.slow
def test_every_campaign_figure_is_fit_to_hand_on(campaign_results: list[GroupResult], tmp_path: Path) -> None:
    swath = [r for r in campaign_results if r.key.hull == "swath"]
    at_t = [r for r in campaign_results if r.key.draft == 1.0]
    drawn = {
        "coefficients": campaign_report._plot_coefficients(swath),
        "b_eq": campaign_report._plot_b_eq(swath),
        "extinction": campaign_report._plot_extinction(swath),
        "period": campaign_report._plot_period(campaign_results),
        "hulls": campaign_report._plot_hulls(at_t),
    }
    for name, fig in drawn.items():
        assert_fit_to_hand_on(fig, name)
    # the coefficients' legend is beside the panels, right of the last one (it covered b1's)
    coefficients = drawn["coefficients"]
    (legend,) = coefficients.legends
    renderer = coefficients.canvas.get_renderer()  # type: ignore[attr-defined]
    assert legend.get_window_extent(renderer).x0 > coefficients.axes[-1].get_window_extent(renderer).x1
    # B̂44 beside B_eq/I: the second panel is the first times each group's I √(B/2g) / (ρ∇B²)
    b_eq, hat = drawn["b_eq"].axes
    assert hat.get_ylabel().startswith("B̂44") and b_eq.get_ylabel() == "B_eq / I (1/s)"
    for result, line, hat_line in zip(swath, b_eq.get_lines()[::2], hat.get_lines()[::2], strict=False):
        factor = result.b44_hat_per_b_eq()
        assert factor is not None
        np.testing.assert_allclose(hat_line.get_ydata(), factor * line.get_ydata(), rtol=1e-12)
    # a group without its hull file (no beam, no inertia): B_eq/I alone
    unknown = [dataclasses.replace(r, hull=None) for r in swath]
    assert len(campaign_report._plot_b_eq(unknown).axes) == 1
    written = campaign_report.write_plots(campaign_results[:2], tmp_path)
    assert all(path.stat().st_size > 0 for path in written)


@pytest.mark.slow
def test_campaign_table_has_b44_hat_beside_b_eq(campaign_results: list[GroupResult]) -> None:
    swath = load_hull("swath")
    for result in campaign_results:
        row = result.summary()
        if result.key.hull != "swath":
            continue
        inertia = swath.displacement_kg * result.key.draft * 9.81 * swath.particulars("roll").gm_m
        inertia /= result.fit.coefficients_["c1"]
        beam, mass = 0.6, swath.displacement_kg * result.key.draft  # [dimensions] beam_m; rho V = the mass
        hand = row["b_eq_per_s"] * inertia * math.sqrt(beam / (2 * 9.81)) / (mass * beam**2)
        assert row["b44_hat"] == pytest.approx(hand, rel=1e-9)
    header = markdown_table(campaign_results).splitlines()[0]
    assert "| B_eq/I 1/s | B̂44 |" in header


@pytest.mark.slow
def test_auv_validation_figure_keeps_its_scores_beside_the_panels() -> None:
    t = np.arange(0.0, 30.0, 0.1)
    states = {
        "theta": 0.1 * np.sin(0.3 * t),
        "q": 0.03 * np.cos(0.3 * t),
        "w": 0.05 * np.sin(0.3 * t),
        "z": 2.0 + 0.5 * np.sin(0.3 * t),
        "delta_s": 0.2 * np.sign(np.sin(0.3 * t)),
    }
    record = StateRecord(t, states, meta={"vehicle": "remus-like test vehicle"})
    results = [
        ValidationResult(label, StateRecord(t, {k: 0.95 * v for k, v in states.items()}), r2)
        for label, r2 in (
            ("identified (LS-SVM)", {"theta": 0.991, "q": 0.973, "w": 0.952, "z": 0.998}),
            ("configured coefficients", {"theta": 0.812, "q": 0.744, "w": 0.701, "z": 0.903}),
        )
    ]
    fig = validation_figure(record, results)
    assert_fit_to_hand_on(fig, "auv validation")


@pytest.mark.slow
def test_the_diagnose_reports_own_figures_are_fit_to_hand_on() -> None:
    """``diagnose.report.figures`` of a real (small) diagnosis: runs named in the recording grammar get
    their condition and run number, the decays start at 0 s although the device clock does not."""
    from tankdaq.diagnose.report import figures
    from tankdaq.diagnose.workflow import Diagnoser

    data = make_decay_set(("damping.quadratic",), seed=22, angles_deg=(15.0, 8.0), duration_s=8.0)
    for k, run in enumerate(data.runs, 1):
        run.t = run.t + DEVICE_T0_S
        run.name = f"swath_T_roll_{k * 7}deg_20261121-14301{k}_run0{k}"
        run.meta["file"] = f"/lab/{run.name}.mcap"
    drawn = figures(Diagnoser(max_steps=0).fit(data.runs))  # the baseline alone: the figures are the point
    for name, fig in drawn.items():
        assert_fit_to_hand_on(fig, name)
    titles = [ax.get_title(loc="left") for ax in drawn["models.png"].axes]
    assert titles == ["swath T roll #1", "swath T roll #2"]
    assert all(ax.get_lines()[0].get_xdata()[0] == 0.0 for ax in drawn["residuals.png"].axes)
    assert drawn["spectrum.png"].axes[0].get_xlabel().startswith("frequency (Hz)")
