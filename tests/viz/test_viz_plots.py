"""PNG report figures: the plotted data, units on the axes, and real PNG files."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from tankdaq.errors import RecordingError
from tankdaq.ident.interval_labels import FIT_STD
from tankdaq.physics.decay import simulate_decay
from tankdaq.viz.plots import decay_fit_figure, save_png, series_figure


def test_decay_figure_draws_degrees_model_and_residual(tmp_path: Path) -> None:
    t = np.linspace(0, 10, 1001)
    measured, _ = simulate_decay({"b1": 0.5, "c1": 30.0}, t, np.radians(8.0))
    model, _ = simulate_decay({"b1": 0.6, "c1": 30.5}, t, np.radians(8.0))
    fig = decay_fit_figure(t, measured, model, axis="pitch", title="swath 1.1T")
    top, bottom = fig.axes
    assert top.get_ylabel() == "pitch angle (deg)" and bottom.get_ylabel() == "residual (deg)"
    assert bottom.get_xlabel() == "time since release (s)" and top.get_title() == "swath 1.1T"
    measured_line, model_line = top.get_lines()
    np.testing.assert_allclose(measured_line.get_ydata(), np.degrees(measured))
    np.testing.assert_allclose(model_line.get_ydata(), np.degrees(model))
    np.testing.assert_allclose(bottom.get_lines()[0].get_ydata(), np.degrees(measured - model), atol=1e-12)
    assert [text.get_text() for text in top.get_legend().get_texts()] == ["measured", "model"]

    png = save_png(fig, tmp_path / "decay.png", dpi=100)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    height, width, _ = matplotlib.image.imread(png).shape
    assert (width, height) == (800, 620)  # 8.0 x 6.2 in at 100 dpi: two panels


def test_decay_figure_without_model_has_one_panel() -> None:
    t = np.linspace(0, 1, 11)
    fig = decay_fit_figure(t, np.radians(np.ones(11)))
    (ax,) = fig.axes
    assert ax.get_xlabel() == "time since release (s)"
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), 1.0)


def test_series_figure_with_error_bars(tmp_path: Path) -> None:
    amplitude = np.array([2.0, 4.0, 6.0, 8.0])
    fig = series_figure(
        amplitude,
        {"T": (amplitude * 0.01, amplitude * 0.001), "1.1T": (amplitude * 0.012, None)},
        xlabel="amplitude (deg)",
        ylabel="B_eq (1/s)",
        interval=FIT_STD,
    )
    (ax,) = fig.axes
    assert ax.get_title() == "(bars: ± (1σ, fit))"  # the bars say what they are
    assert ax.get_xlabel() == "amplitude (deg)" and ax.get_ylabel() == "B_eq (1/s)"
    first, second = ax.containers
    np.testing.assert_allclose(first.lines[0].get_ydata(), amplitude * 0.01)
    assert first.has_yerr and not second.has_yerr
    low_caps, high_caps = first.lines[1]
    np.testing.assert_allclose(high_caps.get_ydata() - low_caps.get_ydata(), amplitude * 0.002)
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["T", "1.1T"]
    assert save_png(fig, tmp_path / "beq.png").stat().st_size > 0
    with pytest.raises(ValueError, match="interval"):  # bars that would not say what they are
        series_figure(amplitude, {"T": (amplitude, amplitude)}, xlabel="a (deg)", ylabel="B (1/s)")


def test_save_into_missing_folder_is_a_one_line_error(tmp_path: Path) -> None:
    fig = decay_fit_figure(np.arange(3.0), np.zeros(3))
    with pytest.raises(RecordingError, match=r"folder .* does not exist"):
        save_png(fig, tmp_path / "nowhere" / "x.png")
