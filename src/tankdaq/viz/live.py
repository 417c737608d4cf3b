"""The live rerun view of a decay: angle, rate, the model fitted so far, its coefficients and residual.

One rerun recording per decay (``new_run``), on the device-time timeline ``t``.
A refit redraws the model over the whole decay, and a time series that gets
new values at old timestamps draws a zig-zag between the old and new curve.
So each fit revision is its own entity (``angle/model/fit_007``): the newest is
drawn bold, the one before it faint (to show what changed), older ones are
hidden. Nothing is drawn twice at one timestamp in one series.
"""

from __future__ import annotations

import os
import shutil
import sys
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Self

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ..errors import InputError
from ..physics.decay import TERM_UNITS
from ..samples import AXIS_FIELDS
from ..store.schemas import interval_pairs

APPLICATION_ID = "tankdaq"
TIMELINE = "t"
URL_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
MODES = ("spawn", "save", "none")

MEASURED_COLOR = (31, 119, 180)
MODEL_COLOR = (214, 39, 40)
PREVIOUS_COLOR = (150, 150, 150, 140)
INTERVAL_COLOR = (31, 119, 180, 90)
EVENT_LEVELS = {"warning": "WARN", "unplug": "ERROR", "gap": "WARN"}


def rerun_executable() -> str | None:
    """The ``rerun`` viewer: on PATH, or beside this Python (a venv that is not activated)."""
    beside = Path(sys.executable).parent / "rerun"
    return shutil.which("rerun") or (str(beside) if beside.is_file() else None)


def default_viewer_mode() -> str:
    """``spawn`` when there is a display and a viewer to show on it, ``save`` (an .rrd) otherwise."""
    has_display = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return "spawn" if has_display and rerun_executable() else "save"


def check_mode(mode: str) -> str:
    """Refuse a viewer mode that is neither spawn, save, none nor a rerun URL (exit 2 at the CLI)."""
    if mode in MODES or mode.startswith(URL_SCHEMES):
        return mode
    raise InputError(
        f"viewer mode {mode!r} not understood: use spawn, save, none, or a URL like rerun+http://127.0.0.1:9876/proxy"
    )


def decay_blueprint(terms: Sequence[str] = ()) -> rrb.Blueprint:
    """Four plots a person reads without clicking, events underneath; side panels collapsed."""
    if terms:
        coefficients: rrb.Container | rrb.TimeSeriesView = rrb.Grid(
            *(
                rrb.TimeSeriesView(origin=f"/coefficients/{term}", name=f"{term} ({TERM_UNITS[term]})")
                for term in terms
            ),
            name="Coefficients",
        )
    else:
        coefficients = rrb.TimeSeriesView(origin="/coefficients", name="Coefficients")
    legend = rrb.PlotLegend(corner="RightTop")
    plots = rrb.Grid(
        rrb.TimeSeriesView(origin="/angle", name="Angle (deg)", plot_legend=legend),
        rrb.TimeSeriesView(origin="/rate", name="Rate (deg/s)", plot_legend=legend),
        coefficients,
        rrb.TimeSeriesView(origin="/residual", name="Residual (deg)", plot_legend=legend),
        grid_columns=2,
    )
    return rrb.Blueprint(
        rrb.Vertical(plots, rrb.TextLogView(origin="/events", name="Events"), row_shares=[5, 1]),
        collapse_panels=True,
    )


class LiveView:
    """Log a decay test to rerun: ``mode`` is spawn, save, none or a rerun URL.

    ``save`` writes one .rrd per run (``rrd_path`` here or in ``new_run``); with
    spawn or a URL an ``rrd_path`` is written as well. ``terms`` gives each
    coefficient its own plot with its unit.
    """

    def __init__(
        self,
        mode: str = "none",
        rrd_path: str | Path | None = None,
        axis: str = "roll",
        terms: Sequence[str] = (),
        spawn_port: int = 9876,
    ) -> None:
        self.mode = check_mode(mode)
        if axis not in AXIS_FIELDS:
            raise InputError(f"axis {axis!r} not understood; use one of: {', '.join(AXIS_FIELDS)}")
        self.axis = axis
        self.terms = tuple(terms)
        self.spawn_port = spawn_port
        self._first_rrd_path = None if rrd_path is None else Path(rrd_path)
        self._spawned = False
        self._rec: rr.RecordingStream | None = None
        self._origin = 0.0
        self.rrd_path: Path | None = None

    # -- runs -------------------------------------------------------------------------------------------

    def new_run(
        self,
        name: str = "decay",
        rrd_path: str | Path | None = None,
        terms: Sequence[str] | None = None,
        time_origin_s: float = 0.0,
    ) -> None:
        """Start a fresh recording (one per decay); the previous one is flushed and closed.

        ``time_origin_s`` (device time, e.g. the release) becomes zero on the view's timeline, so a
        person reads "seconds since release" instead of the sensor's hours since power-up.
        """
        self.close()
        self._origin = float(time_origin_s)
        if terms is not None:
            self.terms = tuple(terms)
        self.rrd_path = None if rrd_path is None else Path(rrd_path)
        if self.mode == "save" and self.rrd_path is None:
            raise InputError("viewer mode 'save' needs a path for the .rrd file")
        self._revision = 0
        self._measured_t: list[np.ndarray] = []
        self._measured_angle: list[np.ndarray] = []
        self._styled_terms: set[str] = set()
        if self.mode == "none":  # no stream at all: a disabled one still warns when flushed or collected
            return
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        self._rec = rec
        blueprint = decay_blueprint(self.terms)
        sinks: list[rr.GrpcSink | rr.FileSink] = []
        if self.mode == "spawn":
            if not self._spawned:
                if rerun_executable() is None:
                    raise InputError("no rerun viewer found to spawn; use --viewer save (an .rrd per run)")
                rec.spawn(port=self.spawn_port, connect=False, hide_welcome_screen=True)
                self._spawned = True
            sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{self.spawn_port}/proxy"))
        elif self.mode.startswith(URL_SCHEMES):
            sinks.append(rr.GrpcSink(self.mode))
        if self.rrd_path is not None:
            sinks.append(rr.FileSink(str(self.rrd_path)))
        rec.set_sinks(*sinks, default_blueprint=blueprint)
        rec.send_recording_name(name)
        self._style_static(rec)

    def _recording(self) -> rr.RecordingStream:
        if self._rec is None:
            self.new_run(rrd_path=self._first_rrd_path)
        assert self._rec is not None
        return self._rec

    def close(self) -> None:
        """Flush and close the current recording (the .rrd is complete afterwards)."""
        if self._rec is not None:
            self._rec.flush(timeout_sec=10.0)
            self._rec.disconnect()
            self._rec = None

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # -- logging ----------------------------------------------------------------------------------------

    def _style_static(self, rec: rr.RecordingStream) -> None:
        for entity in ("angle/measured", "rate/measured"):
            rec.log(
                entity, rr.SeriesLines(colors=[MEASURED_COLOR], widths=[1.5], names=["measured"]), static=True
            )

    def _columns(self, entity: str, t: np.ndarray, values: np.ndarray) -> None:
        self._recording().send_columns(
            entity,
            indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=float) - self._origin)],
            columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=float)),
        )

    def log_samples(self, samples: np.ndarray) -> None:
        """Measured angle and rate of the view's axis, in degrees, against time from the run's origin."""
        if samples.size == 0 or self.mode == "none":
            return
        angle_field, rate_field = AXIS_FIELDS[self.axis]
        self._recording()
        self._measured_t.append(samples["t"].copy())
        self._measured_angle.append(samples[angle_field].copy())
        self._columns("angle/measured", samples["t"], np.degrees(samples[angle_field]))
        self._columns("rate/measured", samples["t"], np.degrees(samples[rate_field]))

    def log_fit(
        self,
        t: np.ndarray,
        predicted_angle: np.ndarray,
        predicted_rate: np.ndarray,
        coefficients: Mapping[str, float],
        ci95: Mapping[str, object] | None = None,
        t_fit: float | None = None,
    ) -> None:
        """A refit: model angle and rate over ``t`` (rad, rad/s), its residual, and the coefficients.

        ``ci95`` per term is [low, high] or a half-width. The coefficients are
        plotted at ``t_fit`` (default: the last time of ``t``) so they converge
        along the same time axis as the decay.
        """
        if self.mode == "none":
            return
        rec = self._recording()
        t = np.asarray(t, dtype=float)
        self._revision += 1
        fit = f"fit_{self._revision:03d}"
        stamp = float(t[-1]) if t_fit is None else float(t_fit)
        label = f"model (fit {self._revision}, t = {stamp - self._origin:.1f} s)"
        curves = {"angle": (t, np.degrees(predicted_angle)), "rate": (t, np.degrees(predicted_rate))}
        if self._measured_t:
            measured_t = np.concatenate(self._measured_t)
            measured = np.degrees(np.concatenate(self._measured_angle))
            order = np.argsort(measured_t, kind="stable")
            inside = (t >= measured_t.min()) & (t <= measured_t.max())  # no residual against extrapolation
            at_t = np.interp(t[inside], measured_t[order], measured[order])
            curves["residual"] = (t[inside], at_t - curves["angle"][1][inside])
        for group, (times, values) in curves.items():
            name = label if group != "residual" else f"residual (fit {self._revision})"
            rec.log(
                f"{group}/model/{fit}",
                rr.SeriesLines(colors=[MODEL_COLOR], widths=[2.0], names=[name]),
                static=True,
            )
            self._columns(f"{group}/model/{fit}", times, values)
            if self._revision >= 2:
                previous = f"{group}/model/fit_{self._revision - 1:03d}"
                rec.log(
                    previous,
                    rr.SeriesLines(colors=[PREVIOUS_COLOR], widths=[1.0], names=["previous fit"]),
                    static=True,
                )
            if self._revision >= 3:
                older = f"{group}/model/fit_{self._revision - 2:03d}"
                rec.log(older, rr.SeriesLines(visible_series=[False]), static=True)
        rec.set_time(TIMELINE, duration=stamp - self._origin)
        intervals = interval_pairs(coefficients, ci95)
        for term, value in coefficients.items():
            entity = f"coefficients/{term}"
            if term not in self._styled_terms:
                rec.log(
                    entity,
                    rr.SeriesLines(
                        colors=[MEASURED_COLOR, INTERVAL_COLOR, INTERVAL_COLOR],
                        widths=[2.0, 1.0, 1.0],
                        names=[
                            f"{term} ({TERM_UNITS.get(term, '')})",
                            f"{term} 95 % low",
                            f"{term} 95 % high",
                        ],
                    ),
                    static=True,
                )
                self._styled_terms.add(term)
            low, high = intervals.get(term, [np.nan, np.nan])
            rec.log(entity, rr.Scalars([float(value), low, high]))

    def log_event(self, kind: str, message: str, t_s: float | None = None) -> None:
        """A run event (release, settled, warning, ...) in the Events panel, at its time."""
        if self.mode == "none":
            return
        rec = self._recording()
        if t_s is not None:
            rec.set_time(TIMELINE, duration=float(t_s) - self._origin)
        rec.log("events", rr.TextLog(f"{kind}: {message}", level=EVENT_LEVELS.get(kind, "INFO")))
