"""The rerun live view, read back from real .rrd files with rerun.chunk.RrdReader."""

from __future__ import annotations

import socket
import subprocess
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rerun.chunk import RrdReader

from tankdaq.errors import InputError
from tankdaq.physics.decay import simulate_decay
from tankdaq.samples import empty_samples
from tankdaq.viz.live import APPLICATION_ID, LiveView
from tankdaq.viz.viewer import default_viewer_mode, rerun_executable

pytestmark = pytest.mark.filterwarnings("ignore:RRD file has no footer")  # a streamed .rrd has none: expected

TRUTH = {"b1": 0.8, "c1": 40.0}


def decay_samples(n: int = 600, rate_hz: float = 100.0) -> np.ndarray:
    samples = empty_samples(n)
    samples["t"] = 10.0 + np.arange(n) / rate_hz
    samples["roll"], samples["p"] = simulate_decay(TRUTH, samples["t"], np.radians(6.0))
    return samples


def read_rrd(path: Path) -> tuple[dict[str, list[dict[str, Any]]], dict[str, dict[str, Any]], list[str]]:
    """Temporal rows per entity, the latest static components per entity, and the blueprint's titles."""
    reader = RrdReader(path)
    (recording,) = reader.recordings()
    assert recording.application_id == APPLICATION_ID
    rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
    static: dict[str, dict[str, Any]] = defaultdict(dict)
    for chunk in reader.stream(store=recording).to_chunks():
        batch = chunk.to_record_batch()
        columns = {name: batch.column(name).to_pylist() for name in batch.schema.names if ":" in name}
        if "t" in batch.schema.names:
            columns["t"] = batch.column("t").cast("int64").to_pylist()  # ns: timedelta would round to us
        table = [dict(zip(columns, values, strict=True)) for values in zip(*columns.values(), strict=True)]
        if chunk.is_static:
            for row in table:
                static[chunk.entity_path].update({k: v for k, v in row.items() if ":" in k and v is not None})
        else:
            rows[chunk.entity_path].extend(table)
    views = []
    for blueprint in reader.blueprints():
        for chunk in reader.stream(store=blueprint).to_chunks():
            batch = chunk.to_record_batch()
            for column in ("ViewBlueprint:display_name", "ContainerBlueprint:display_name"):
                if column in batch.schema.names:
                    views += [name[0] for name in batch.column(column).to_pylist() if name]
    return rows, static, views


def series(rows: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """(time in s, scalars) of an entity's rows, sorted by time."""
    ordered = sorted(rows, key=lambda row: row["t"])
    times = np.array([row["t"] / 1e9 for row in ordered])
    return times, np.array([row["Scalars:scalars"] for row in ordered], dtype=float)


def log_decay(view: LiveView, samples: np.ndarray, fits: int) -> list[dict[str, float]]:
    """Samples, a release event, then ``fits`` refits converging to the truth."""
    view.log_samples(samples[:200])
    view.log_event("release", "released at 6 deg", t_s=float(samples["t"][0]))
    view.log_samples(samples[200:])
    coefficient_sets = []
    for k in range(fits):
        coefficients = {name: value * (1 + 0.2 / (k + 1)) for name, value in TRUTH.items()}
        angle, rate = simulate_decay(coefficients, samples["t"], np.radians(6.0))
        view.log_fit(samples["t"], angle, rate, coefficients, ci95={"b1": 0.1 / (k + 1), "c1": [39.0, 41.5]})
        coefficient_sets.append(coefficients)
    return coefficient_sets


def test_saved_rrd_holds_measurement_fits_and_blueprint(tmp_path: Path) -> None:
    samples = decay_samples()
    with LiveView("save", rrd_path=tmp_path / "run.rrd", terms=["b1", "c1"]) as view:
        coefficient_sets = log_decay(view, samples, fits=3)
    rows, static, views = read_rrd(tmp_path / "run.rrd")

    t, angle_deg = series(rows["/angle/measured"])
    np.testing.assert_allclose(t, samples["t"], atol=1e-9)
    np.testing.assert_allclose(angle_deg[:, 0], np.degrees(samples["roll"]), rtol=1e-12)
    _, rate_deg = series(rows["/rate/measured"])
    np.testing.assert_allclose(rate_deg[:, 0], np.degrees(samples["p"]), rtol=1e-12)

    # every refit is its own series: no timestamp holds two model values
    last_angle, _ = simulate_decay(coefficient_sets[-1], samples["t"], np.radians(6.0))
    for revision in (1, 2, 3):
        t_model, model = series(rows[f"/angle/fits/fit_{revision:03d}"])
        assert np.unique(t_model).size == t_model.size == samples.size
    np.testing.assert_allclose(model[:, 0], np.degrees(last_angle), rtol=1e-12)
    assert static["/angle/fits/fit_003"]["SeriesLines:names"] == ["model (fit 3, t = 16.0 s)"]
    assert static["/angle/fits/fit_002"]["SeriesLines:names"] == ["previous fit"]
    assert static["/angle/fits/fit_001"]["SeriesLines:names"] == ["earlier fits"]
    # never hidden: a viewer keeps hidden series in its blueprint, and a later decay's fit_001 would start
    # hidden there (a short decay's final model never drawn)
    assert not any("SeriesLines:visible_series" in components for components in static.values())

    _, residual = series(rows["/residual/fits/fit_003"])
    np.testing.assert_allclose(residual[:, 0], np.degrees(samples["roll"] - last_angle), atol=1e-9)

    t_fit, b1 = series(rows["/coefficients/b1"])
    assert b1.shape == (3, 3)  # value, low, high at each refit
    np.testing.assert_allclose(b1[:, 0], [c["b1"] for c in coefficient_sets])
    np.testing.assert_allclose(b1[:, 2] - b1[:, 1], [0.2, 0.1, 0.2 / 3])
    np.testing.assert_allclose(t_fit, samples["t"][-1])
    assert static["/coefficients/b1"]["SeriesLines:names"][0] == "b1 (1/s)"

    (event,) = rows["/events"]
    assert event["TextLog:text"] == ["release: released at 6 deg"]
    for title in ("Angle (deg)", "Rate (deg/s)", "Coefficients", "Residual (deg)", "b1 (1/s)", "Events"):
        assert title in views


def test_one_rrd_per_run(tmp_path: Path) -> None:
    samples = decay_samples(100)
    view = LiveView("save", terms=["b1"])
    for run in (1, 2):
        view.new_run(f"run {run}", rrd_path=tmp_path / f"run{run}.rrd")
        view.log_samples(samples[: 50 * run])
    view.close()
    ids = set()
    for run in (1, 2):
        reader = RrdReader(tmp_path / f"run{run}.rrd")
        (recording,) = reader.recordings()
        ids.add(recording.recording_id)
        rows, _, _ = read_rrd(tmp_path / f"run{run}.rrd")
        assert len(rows["/angle/measured"]) == 50 * run
    assert len(ids) == 2


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_url_mode_streams_to_a_local_server(tmp_path: Path) -> None:
    executable = rerun_executable()
    assert executable is not None
    port = free_port()
    received = tmp_path / "received.rrd"
    server = subprocess.Popen(
        [executable, "--serve-grpc", "--bind", "127.0.0.1", "--port", str(port), "--save", str(received)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        for _ in range(300):  # wait until the server listens
            with socket.socket() as probe:
                if probe.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.05)
        samples = decay_samples(300)
        with LiveView(f"rerun+http://127.0.0.1:{port}/proxy") as view:
            view.log_samples(samples)
        rows: dict[str, list[dict[str, Any]]] = {}
        for _ in range(200):  # the server writes what it got; wait for all of it
            if received.exists() and received.stat().st_size > 0:
                try:
                    rows, _, _ = read_rrd(received)
                except (ValueError, OSError, RuntimeError):  # caught mid-write by the server: read again
                    rows = {}
                if len(rows.get("/angle/measured", [])) == samples.size:
                    break
            time.sleep(0.05)
        assert len(rows["/angle/measured"]) == samples.size
    finally:
        server.terminate()
        server.wait(timeout=10)
    with socket.socket() as probe:  # the server itself was stopped, not a wrapper around it (issue 13)
        assert probe.connect_ex(("127.0.0.1", port)) != 0


def test_none_mode_logs_nothing_and_costs_nothing(tmp_path: Path) -> None:
    with LiveView("none", rrd_path=tmp_path / "x.rrd") as view:
        log_decay(view, decay_samples(100), fits=1)
    assert not (tmp_path / "x.rrd").exists()


def test_bad_modes_are_input_errors() -> None:
    with pytest.raises(InputError, match="viewer mode 'screen'"):
        LiveView("screen")
    with pytest.raises(InputError, match="needs a path"):
        LiveView("save").log_samples(decay_samples(10))
    with pytest.raises(InputError, match="axis 'heave'"):
        LiveView("none", axis="heave")


def test_default_mode_spawns_only_with_a_display(monkeypatch: pytest.MonkeyPatch) -> None:
    assert rerun_executable() is not None  # the venv ships the viewer
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert default_viewer_mode() == "save"
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    assert default_viewer_mode() == "spawn"


def test_a_forecast_beyond_the_measurement_has_no_residual_there(tmp_path: Path) -> None:
    samples = decay_samples(300)
    ahead = 10.0 + np.arange(500) / 100.0  # two seconds further than measured
    angle, rate = simulate_decay(TRUTH, ahead, np.radians(6.0))
    with LiveView("save", rrd_path=tmp_path / "ahead.rrd") as view:
        view.log_samples(samples)
        view.log_fit(ahead, angle, rate, TRUTH)
    rows, _, _ = read_rrd(tmp_path / "ahead.rrd")
    t_model, _ = series(rows["/angle/fits/fit_001"])
    t_residual, residual = series(rows["/residual/fits/fit_001"])
    assert t_model.size == 500 and t_residual.size == 300
    np.testing.assert_allclose(residual[:, 0], 0.0, atol=1e-9)  # the truth fits its own samples


def test_any_registered_term_renders_with_its_unit(tmp_path: Path) -> None:
    """``record --model b1,c1,fc``: fc is not a state term; its title comes from the one term table."""
    samples = decay_samples(200)
    angle, rate = simulate_decay(TRUTH, samples["t"], np.radians(6.0))
    with LiveView("save", rrd_path=tmp_path / "fc.rrd", terms=["b1", "c1", "fc"]) as view:
        view.log_samples(samples)
        view.log_fit(samples["t"], angle, rate, {**TRUTH, "fc": 0.002}, ci95={"fc": 0.001})
    rows, static, views = read_rrd(tmp_path / "fc.rrd")
    assert "fc (rad/s^2)" in views
    assert static["/coefficients/fc"]["SeriesLines:names"][0] == "fc (rad/s^2)"
    (fc,) = series(rows["/coefficients/fc"])[1]
    np.testing.assert_allclose(fc, [0.002, 0.001, 0.003])


def test_the_viewer_of_the_installed_rerun_sdk_is_found_off_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run as .venv/bin/tankdaq with nothing on PATH: the viewer binary shipped with rerun-sdk."""
    import rerun
    import rerun_cli

    monkeypatch.setenv("PATH", "")
    executable = rerun_executable()
    assert executable is not None and Path(executable).parent == Path(rerun_cli.__file__).parent
    version = subprocess.run([executable, "--version"], capture_output=True, text=True, timeout=60)
    assert f"rerun-cli {rerun.__version__}" in version.stdout
