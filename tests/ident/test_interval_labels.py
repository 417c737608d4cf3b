"""Every interval says what it is (issue 38 item 2): each figure tankdaq draws with bars or bands names their
coverage and kind in its legend or caption (read from the matplotlib artists, not the pixels); the tables,
``--json`` and the DataFrames say it too, from one convention (``ident.interval_labels``)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.container import ErrorbarContainer
from matplotlib.figure import Figure
from matplotlib.legend import Legend

import tankdaq
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
from tankdaq.ident.imo_table import initial_angle_deg
from tankdaq.ident.interval_labels import (
    ALL_LABELS,
    ANGLES_RANGE,
    EXPANDED_U,
    FIT_95,
    FIT_STD,
    STANDARD_U,
    Coverage,
    IntervalSource,
    kind_of,
)
from tankdaq.ident.report import text_report
from tankdaq.viz import campaign_report, diagnose_view, plots, report_figures


def intervals_drawn(fig: Figure) -> int:
    """How many error-bar sets and bands (fill_between) the figure draws."""
    count = 0
    for ax in fig.axes:
        count += sum(
            1 for c in ax.containers if isinstance(c, ErrorbarContainer) and (c.has_yerr or c.has_xerr)
        )
        count += sum(1 for c in ax.collections if isinstance(c, PolyCollection))
    return count


def captions(fig: Figure) -> list[str]:
    """The texts that say what a figure shows: legends (entries and titles), panel titles, the suptitle."""
    texts = [fig._suptitle.get_text()] if fig._suptitle is not None else []  # type: ignore[attr-defined]
    texts += [ax.get_title() for ax in fig.axes]
    for legend in fig.findobj(Legend):
        texts += [legend.get_title().get_text(), *(t.get_text() for t in legend.get_texts())]
    return [text for text in texts if text]


def said_labels(fig: Figure) -> set[str]:
    """The interval labels (``ident.interval_labels``) the figure's legends and captions hold."""
    return {label.text for label in ALL_LABELS for text in captions(fig) if label.text in text}


@pytest.fixture(scope="module")
def campaign_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One hull (swath: beam and displacement), roll, two drafts, two angles: small and fast to fit."""
    folder = tmp_path_factory.mktemp("labels_campaign")
    write_simulated_campaign(folder, ["swath"], "roll", [1.0, 1.1], [6.0, 10.0], "csv", seed=3)
    return folder


@pytest.fixture(scope="module")
def results(campaign_folder: Path) -> list[GroupResult]:
    runs = [run for path in find_recordings([campaign_folder]) for run in read_campaign_runs(path)]
    groups = group_runs(runs)
    return identify_groups(groups, model="b1,b2,c1", hulls=find_campaign_hulls(k.hull for k in groups))


def every_figure(results: list[GroupResult]) -> dict[str, Figure]:
    """Every figure tankdaq draws that can hold an interval, from small inputs."""
    amplitudes = np.array([2.0, 4.0, 6.0])
    band = (0.1 + 0.01 * amplitudes, 0.002 * amplitudes)
    decrement = (np.radians(amplitudes), np.radians(0.05 * amplitudes))
    drawn = {name: campaign_report._PLOTS[name](results) for name in campaign_report._PLOTS}
    drawn["damping"] = diagnose_view.damping_figure(
        amplitudes, {"measured": band, "corrected": band}, {"measured": decrement}
    )
    drawn["series"] = plots.series_figure(
        amplitudes, {"T": band}, xlabel="amplitude (deg)", ylabel="B_eq (1/s)", interval=FIT_STD
    )
    drawn["decay"] = plots.decay_fit_figure(np.arange(0.0, 2.0, 0.01), np.zeros(200), np.zeros(200))
    (group, *_) = results  # the report's damping figure of a fit, its band and bars as the report draws them
    coefficients, covariance = group.fit.coefficients_, np.asarray(group.fit.covariance_)
    bertin = [(0.05 * a, 0.001) for a in amplitudes]
    drawn["report damping"] = report_figures.damping_figure(
        coefficients, covariance, amplitudes, bertin, FIT_95, "report"
    )
    return drawn


@pytest.mark.slow
def test_every_figure_that_draws_an_interval_says_its_coverage_and_kind(results: list[GroupResult]) -> None:
    drawn = every_figure(results)
    with_intervals = {name for name, fig in drawn.items() if intervals_drawn(fig)}
    # the check sees the intervals: these figures draw bars or bands, the others none
    drawing = {"coefficients", "hulls", "b_eq", "period", "damping", "series", "report damping"}
    assert with_intervals == drawing
    for name in with_intervals:
        said = said_labels(drawn[name])
        assert said, f"{name}: its intervals do not say their coverage ({captions(drawn[name])})"
        coverages = {c.value for c in Coverage}
        assert any(c in text for text in said for c in coverages), name
    # each says its own: 95 % fit bars beside the tables' 1σ, half-ranges as a range
    assert said_labels(drawn["coefficients"]) == {FIT_95.text} == said_labels(drawn["b_eq"])
    assert said_labels(drawn["period"]) == {ANGLES_RANGE.text}
    assert said_labels(drawn["damping"]) == {FIT_95.text} and said_labels(drawn["series"]) == {FIT_STD.text}
    assert said_labels(drawn["report damping"]) == {FIT_95.text}
    (bars,) = drawn["report damping"].axes[1].containers  # Bertin N's bars: 1.96 sigma, as said
    low, high = bars.lines[1]
    half = (np.asarray(high.get_ydata(), dtype=float) - np.asarray(low.get_ydata(), dtype=float)) / 2
    np.testing.assert_allclose(half, 1.96 * 0.001, rtol=1e-12)


@pytest.mark.slow
def test_bars_are_what_their_label_says_and_the_angle_axis_is_measured(results: list[GroupResult]) -> None:
    (group, *_) = results
    nominal = dataclasses.replace(
        group, key=dataclasses.replace(group.key, angle_deg=8.0)
    )  # asked 8, released 6
    fig = campaign_report._plot_coefficients([nominal])
    ax = fig.axes[0]
    (bars,) = ax.containers
    measured = initial_angle_deg(group.runs, group.fit.offsets_)
    assert measured == pytest.approx(6.0, abs=0.05)
    np.testing.assert_allclose(np.asarray(bars.lines[0].get_xdata(), dtype=float), [measured])
    assert ax.get_xlabel() == "initial angle, measured (deg)"
    low, high = bars.lines[1]
    term = group.fit.terms_[0]
    half = (np.asarray(high.get_ydata(), dtype=float) - np.asarray(low.get_ydata(), dtype=float)) / 2
    np.testing.assert_allclose(half, 1.96 * group.fit.std_[term], rtol=1e-12)  # 95 %: 1.96 sigma
    period = campaign_report._plot_period(results)
    (line,) = period.axes[0].containers
    periods = [2 * math.pi / math.sqrt(r.fit.coefficients_["c1"]) for r in results if r.key.draft == 1.0]
    low, high = line.lines[1]
    assert (float(high.get_ydata()[0]) - float(low.get_ydata()[0])) / 2 == pytest.approx(
        np.ptp(periods) / 2
    )  # a half-range


def test_the_convention_holds_the_budgets_labels_and_each_kind() -> None:
    assert STANDARD_U.text == "u (1σ, standard)" and EXPANDED_U.text == "U (k=2, ≈95 %, expanded)"
    assert (
        FIT_STD.text == "± (1σ, fit)" and FIT_95.half_width(1.0) == 1.96 and EXPANDED_U.half_width(0.5) == 1.0
    )
    with pytest.raises(ValueError, match="range"):
        ANGLES_RANGE.half_width(1.0)
    assert len({label.text for label in ALL_LABELS}) == len(ALL_LABELS)
    docs = (Path(__file__).resolve().parents[2] / "docs" / "intervals.md").read_text()
    assert kind_of("moving-block bootstrap, 100 replicas") is IntervalSource.BOOTSTRAP
    assert kind_of("repeat runs, 3 runs") is IntervalSource.REPEATS and kind_of("hac") is IntervalSource.FIT
    for label in ALL_LABELS:
        assert label.coverage.value in docs and label.kind.value in docs


@pytest.mark.slow
def test_tables_json_and_dataframes_say_what_their_intervals_are(
    campaign_folder: Path, results: list[GroupResult], tmp_path: Path
) -> None:
    assert f"Every ± is {FIT_STD.text}" in markdown_table(results)
    found = tankdaq.campaign(campaign_folder, "b1,b2,c1", report=tmp_path / "report")
    document = json.loads(found.to_json())
    assert document["intervals"]["groups: <column>_std"] == FIT_STD.text
    assert found.table.attrs["intervals"]["b1_std"] == FIT_STD.text
    assert {row["interval"] for table in document["imo"] for row in table["rows"] if row["reached"]} <= {
        label.text for label in ALL_LABELS
    }
    frame = found.imo_table
    assert {"amplitude_deg", "bertin_n_per_deg", "bertin_n_std", "interval"} <= set(frame.columns)
    assert set(frame["draft"]) == {"T", "1.1T"} and frame.attrs["missing"]  # 6 and 10 deg reach 10 at most
    report = (tmp_path / "report" / "campaign.md").read_text()
    assert FIT_STD.text in report and "IMO table" in report and "not reached" in found.text()


@pytest.mark.slow
def test_identify_says_the_kind_of_its_intervals(results: list[GroupResult]) -> None:
    from tankdaq.ident.report import summarize

    (group, *_) = results
    summary = summarize(group.fit, group.runs)
    assert summary.interval_labels == {"std": "± (1σ, fit)", "ci95": "± (95 %, fit)"}
    assert "(std ± (1σ, fit), interval ± (95 %, fit):" in text_report(summary)
