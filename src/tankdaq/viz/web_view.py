"""The live view a tablet or phone shows (``--viewer web``): ``LiveView`` streaming to the recorder's web
viewer server (``viz.web_viewer``), laid out in portrait, decimated, with the operator's panel.

What differs from the desk's view: one recording for the whole run (``WebStream.recording_id``; the
view processes that follow one another continue it), not one per decay: rerun 0.41's web viewer selects
none when a page connects to a server holding several, so a page opened late, or reloaded mid-decay,
would show nothing. Its timeline is the device's clock (decays one after another, never overlapping),
and the plots show the last ``WINDOW_S`` up to the time cursor, which follows the live data: the
current decay from its release. Each fit is its own entity as on the desk, under its decay's name.
A blueprint of its own (the operator's panel on top, the angle large, rate, coefficients and residual as
tabs, the events); samples and fitted curves at ``WEB_RATE_HZ`` (a screen needs no more; the MCAP keeps
every sample); the panel (``log_panel``: markdown from ``acquire.live_panel``) from the start, between
decays too. No .rrd: ``web+save`` is this view beside a saving one. Bounded by the server's memory
limit (the oldest first).
"""

from __future__ import annotations

import re
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .live import (
    APPLICATION_ID,
    CLOSE_LIMIT_S,
    CLOSE_STALL_S,
    FLUSH_TIMEOUT_S,
    MEASURED_COLOR,
    TIMELINE,
    LiveView,
    set_sinks_with_blueprint,
    term_title,
)
from .viewer import url_listening
from .web_viewer import WEB_RATE_HZ

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

#: A sample a hair before a slot's start (floating-point time) counts in that slot.
SLOT_TOLERANCE = 1e-6
#: The operator's panel's entity (a markdown document).
PANEL = "session"
#: The plots show this much device time up to the cursor: a decay from its release, with its hold.
WINDOW_S = 60.0
#: Samples go to the server this much device time at a time, and what is logged row by row at most this
#: often (s): a page takes in its data message by message between frames, slowly where WebGL is drawn in
#: software, so fewer, larger messages keep it up with the decay.
SEND_S = 0.5
#: A refit is shown at most this often (device s; a decay's final fit always): each redraws the decay.
FIT_EVERY_S = 2.0


def tablet_blueprint(terms: Sequence[str] = ()) -> rrb.Blueprint:
    """Portrait: the panel, the angle and its model large, then rate, coefficients and residual as tabs,
    the events last; the plots the last ``WINDOW_S``; side panels collapsed (no room on a phone)."""
    import rerun.blueprint as rrb

    legend = rrb.PlotLegend(corner="LeftBottom")  # the newest data is drawn on the right
    window = rrb.VisibleTimeRange(
        TIMELINE,
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-WINDOW_S),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0),
    )

    def plot(origin: str, name: str) -> rrb.TimeSeriesView:
        return rrb.TimeSeriesView(origin=origin, name=name, plot_legend=legend, time_ranges=window)

    coefficients = [plot(f"/coefficients/{t}", term_title(t)) for t in terms]
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.TextDocumentView(origin=f"/{PANEL}", name="Operator"),
            plot("/angle", "Angle (deg)"),
            rrb.Tabs(
                plot("/rate", "Rate (deg/s)"),
                *(coefficients or [plot("/coefficients", "Coefficients")]),
                plot("/residual", "Residual (deg)"),
            ),
            rrb.TextLogView(origin="/events", name="Events"),
            row_shares=[3, 5, 3, 1],
        ),
        collapse_panels=True,
    )


def decimate(t: np.ndarray, rate_hz: float, last_bin: float) -> tuple[np.ndarray, float]:
    """Which of the times ``t`` (s, increasing) to keep for ``rate_hz``: the first of each 1/rate slot,
    a slot counted once over blocks (``last_bin``: the last slot kept so far, -inf at first). Returns
    the mask and the new last slot."""
    slots = np.floor(np.asarray(t, dtype=float) * rate_hz + SLOT_TOLERANCE)
    previous = np.concatenate(([last_bin], slots[:-1]))
    keep = slots > np.maximum.accumulate(previous)
    return keep, float(max(last_bin, slots.max())) if slots.size else last_bin


class WebLiveView(LiveView):
    """``LiveView`` for the web viewer: ``mode`` is the data server's URL, ``recording_id`` the run's one
    recording (see the module docstring)."""

    blueprint = staticmethod(tablet_blueprint)

    def __init__(
        self, mode: str, *args: Any, recording_id: str = "", rate_hz: float = WEB_RATE_HZ, **kwargs: Any
    ) -> None:
        super().__init__(mode, *args, **kwargs)
        self.recording_id = recording_id or str(uuid.uuid4())
        self.rate_hz = rate_hz
        self._last_slot = -np.inf
        self._pending: list[np.ndarray] = []  # decimated samples not sent yet (the view thread's)
        self._fit_shown_t = -np.inf  # the caller's: the device time of the last refit shown

    def new_run(
        self,
        name: str = "decay",
        rrd_path: str | Path | None = None,
        terms: Sequence[str] | None = None,
        time_origin_s: float = 0.0,
    ) -> None:
        """As ``LiveView.new_run``: a decay, in the run's one recording (no .rrd)."""
        self._fit_shown_t = -np.inf
        super().new_run(name, None, terms, time_origin_s)

    def log_fit(
        self,
        t: np.ndarray,
        predicted_angle: np.ndarray,
        predicted_rate: np.ndarray,
        coefficients: Mapping[str, float],
        ci95: Mapping[str, object] | None = None,
        t_fit: float | None = None,
        final: bool = False,
    ) -> None:
        """As ``LiveView.log_fit``, a refit within ``FIT_EVERY_S`` of the last one shown left out."""
        stamp = t_fit if t_fit is not None else float(t[-1]) if len(t) else -np.inf
        if not final and stamp - self._fit_shown_t < FIT_EVERY_S:
            return
        self._fit_shown_t = stamp
        super().log_fit(t, predicted_angle, predicted_rate, coefficients, ci95, t_fit, final)

    def log_panel(self, markdown: str, t_s: float) -> None:
        """The operator's panel now (device time ``t_s``); dropped when the view is behind."""
        if self.mode != "none":
            self._jobs().put(lambda: self._log_panel(markdown, t_s), droppable=True)

    def close(self, stall_s: float = CLOSE_STALL_S, limit_s: float = CLOSE_LIMIT_S) -> None:
        """As ``LiveView.close``; the run's recording is flushed and let go last (pages keep what they
        hold; the server keeps it for the next view process)."""
        if self._feed is not None:
            self._feed.put(self._finish, droppable=False)
        super().close(stall_s, limit_s)

    # -- the view thread's side --------------------------------------------------------------------------

    def _open_run(self, name: str, rrd_path: Path | None, terms: Sequence[str], origin: float) -> None:
        """A decay in the run's recording: its samples and fits go on along the device's clock, its fits
        under its own name (``angle/fits/<name>/fit_001``: none drawn on into another decay's)."""
        self._send_samples()
        self._last_slot = -np.inf
        self._revision = 0
        self._fits = re.sub(r"[^A-Za-z0-9_]", "_", name) + "/"
        self._measured_t: list[np.ndarray] = []
        self._measured_angle: list[np.ndarray] = []
        self._stream(terms)

    def _stream(self, terms: Sequence[str]) -> rr.RecordingStream | None:
        """The run's recording, opened at the first thing shown (the panel before a release, or one)."""
        import rerun as rr

        if self._rec is not None or self._live_url is None:
            return self._recording()
        self._origin = 0.0
        self._styled_terms: set[str] = set()
        self._streaming = url_listening(self._live_url)
        if not self._streaming:
            self._note_once("unserved", f"no web viewer server at {self._live_url}: nothing is shown")
            return None
        rec = rr.RecordingStream(
            APPLICATION_ID,
            recording_id=self.recording_id,
            batcher_config=rr.ChunkBatcherConfig(flush_tick=SEND_S),
        )
        self._rec = rec  # kept referenced: a collected stream closes its sinks
        set_sinks_with_blueprint(rec, self._sinks(), self.blueprint(terms or self.terms))
        rec.send_recording_name("tankdaq live")
        for entity in ("angle/measured", "rate/measured"):
            rec.log(
                entity, rr.SeriesLines(colors=[MEASURED_COLOR], widths=[1.5], names=["measured"]), static=True
            )
        return rec

    def _end_run(self) -> None:
        """The decay's last update delivered, its traces ended (a clear just after its last sample: no line
        drawn across to the next decay's); the recording stays open for the panel and the next."""
        import rerun as rr

        self._send_samples()
        rec = self._rec
        if rec is None:
            return
        if self._measured_t:
            rec.set_time(TIMELINE, duration=float(self._measured_t[-1][-1]) + 1.0 / self.rate_hz)
            for entity in ("angle/measured", "rate/measured"):
                rec.log(entity, rr.Clear(recursive=False))
        try:
            rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as exc:  # the server stalls or is gone: not used again
            self.on_note(self._flush_failed(str(exc)))
            self._drop_recording()

    def _finish(self) -> None:
        self._end_run()
        self._drop_recording()

    def _log_samples(self, samples: np.ndarray) -> None:
        keep, self._last_slot = decimate(samples["t"], self.rate_hz, self._last_slot)
        if keep.any():
            self._pending.append(samples[keep])
        if self._pending and self._pending[-1]["t"][-1] - self._pending[0]["t"][0] >= SEND_S:
            self._send_samples()

    def _send_samples(self) -> None:
        pending, self._pending = self._pending, []
        if pending:
            super()._log_samples(np.concatenate(pending))

    def _log_fit(
        self,
        t: np.ndarray,
        predicted_angle: np.ndarray,
        predicted_rate: np.ndarray,
        coefficients: Mapping[str, float],
        ci95: Mapping[str, object],
        t_fit: float | None,
    ) -> None:
        """A refit's curves at the web rate too (each redraws the decay so far), after the samples so far."""
        self._send_samples()
        keep, _ = decimate(t, self.rate_hz, -np.inf)
        if keep.size:
            keep[-1] = True  # the curve to its end
        at = (t[keep], predicted_angle[keep], predicted_rate[keep])
        super()._log_fit(*at, coefficients, ci95, t_fit)

    def _log_panel(self, markdown: str, t_s: float) -> None:
        import rerun as rr

        rec = self._stream(self.terms)
        if rec is None:
            return
        rec.set_time(TIMELINE, duration=t_s)
        rec.log(PANEL, rr.TextDocument(markdown, media_type=rr.MediaType.MARKDOWN))
