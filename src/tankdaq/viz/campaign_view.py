"""The campaign panel of a guided test session: the campaign's answer as it grows.

One rerun recording for the whole session (``campaign.rrd`` in the session folder, and the live
viewer when one listens), beside the per-decay recordings of ``viz.live``:

- each coefficient against the release angle, one series per draft (the seeds' Fig. 5);
- B_eq at the release amplitude against that amplitude, one series per draft;
- the test matrix, one dot per condition coloured by its status (to do, under way, accepted,
  rejected, skipped), labelled with the repeats kept.

Rerun plots series against a timeline, so the x axis of the two plots is a sequence timeline
``release_angle_deg`` holding the nominal angle in whole degrees (a half-degree plan angle is drawn
at its nearest degree; the session log and the report keep the exact value). The matrix is static:
it is the same on every timeline. Like the live view, every call only queues a job for one
background thread (``viz.view_feed.ViewFeed``): the session never waits for rerun.
"""

from __future__ import annotations

import contextlib
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from .live import APPLICATION_ID, CLOSE_LIMIT_S, CLOSE_STALL_S, term_title, unfinished_note
from .view_feed import ViewFeed
from .viewer import URL_SCHEMES, check_mode, url_listening

ANGLE_TIMELINE = "release_angle_deg"
STATUS_COLORS = {
    "to do": (160, 160, 160),
    "under way": (31, 119, 180),
    "accepted": (44, 160, 44),
    "rejected": (214, 39, 40),
    "skipped": (255, 127, 14),
}
DRAFT_COLORS = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189))


def campaign_blueprint(terms: Sequence[str], angles_deg: Sequence[float], drafts: int) -> rrb.Blueprint:
    """Coefficients and B_eq against the release angle (the plan's angles with a margin), the matrix
    (angles x ``drafts``) beside them."""
    low, high = round(min(angles_deg)), round(max(angles_deg))
    margin = max(1, (high - low) // 5)
    x_axis = rrb.TimeAxis(
        view_range=rrb.components.TimeRange(
            start=rr.TimeRangeBoundary.absolute(seq=low - margin),
            end=rr.TimeRangeBoundary.absolute(seq=high + margin),
        )
    )
    plots = [
        rrb.TimeSeriesView(
            origin=f"/campaign/coefficients/{term}", name=f"{term_title(term)} vs angle", axis_x=x_axis
        )
        for term in terms
    ]
    plots.append(
        rrb.TimeSeriesView(origin="/campaign/b_eq", name="B_eq (1/s) vs amplitude (deg)", axis_x=x_axis)
    )
    angles = len(angles_deg)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Grid(*plots, name="Campaign"),
            rrb.Spatial2DView(
                origin="/campaign/matrix",
                name="Test matrix (angle across, draft down)",
                visual_bounds=rrb.VisualBounds2D(x_range=[-0.6, angles - 0.4], y_range=[-0.6, drafts - 0.4]),
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=ANGLE_TIMELINE, state="collapsed"),
        collapse_panels=True,
    )


class CampaignView:
    """Log the campaign panel: ``mode`` spawn, save, none or a rerun URL (as ``viz.live.LiveView``).

    ``drafts`` (labels) and ``angles_deg`` lay out the matrix; ``rrd_path`` is written in every mode
    but none. With spawn or a URL the panel also goes to the viewer listening at ``viewer_url`` when
    the session starts.
    """

    def __init__(
        self,
        mode: str,
        rrd_path: Path | None,
        drafts: Sequence[str],
        angles_deg: Sequence[float],
        terms: Sequence[str],
        viewer_url: str | None = None,
        on_note: Callable[[str], None] | None = None,
    ) -> None:
        self.mode = check_mode(mode)
        self.drafts = list(drafts)
        self.angles_deg = list(angles_deg)
        self.terms = tuple(terms)
        self.on_note = on_note or (lambda _line: None)
        self._status: dict[tuple[str, float], tuple[str, str]] = {
            (d, a): ("to do", "") for d in self.drafts for a in self.angles_deg
        }
        self._styled: set[str] = set()
        self._rec: rr.RecordingStream | None = None
        self._feed: ViewFeed | None = None
        if self.mode == "none":
            return
        self._feed = ViewFeed(on_error=lambda exc: self.on_note(f"campaign panel update failed ({exc})"))
        url = self.mode if self.mode.startswith(URL_SCHEMES) else viewer_url
        self._feed.put(lambda: self._open(rrd_path, url), droppable=False)

    def _open(self, rrd_path: Path | None, url: str | None) -> None:
        sinks: list[rr.GrpcSink | rr.FileSink] = []
        if rrd_path is not None:
            sinks.append(rr.FileSink(str(rrd_path)))
        if url is not None and self.mode != "save" and url_listening(url):
            sinks.append(rr.GrpcSink(url))
        if not sinks:
            return
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        rec.set_sinks(
            *sinks,
            default_blueprint=campaign_blueprint(self.terms, self.angles_deg, len(self.drafts)),
        )
        rec.send_recording_name("campaign")
        self._rec = rec
        self._log_matrix()

    def _put(self, job: Callable[[], None]) -> None:
        if self._feed is not None:
            self._feed.put(job, droppable=False)

    # -- the session's side: queue and return ---------------------------------------------------------

    def set_status(self, draft: str, angle_deg: float, status: str, label: str = "") -> None:
        """A condition's status (a key of ``STATUS_COLORS``) and a short label (``1/2 kept``)."""
        self._status[(draft, angle_deg)] = (status, label)
        self._put(self._log_matrix)

    def accepted(
        self, draft: str, angle_deg: float, coefficients: Mapping[str, float], b_eq_per_s: float
    ) -> None:
        """A condition is done: one point per coefficient and one B_eq point at its angle."""
        values = dict(coefficients)
        self._put(lambda: self._log_condition(draft, angle_deg, values, b_eq_per_s))

    def close(self, stall_s: float = CLOSE_STALL_S, limit_s: float = CLOSE_LIMIT_S) -> None:
        """Finish the queue and flush the recording: the .rrd is complete after."""
        feed, self._feed = self._feed, None
        if feed is None:
            return
        feed.put(self._flush, droppable=False)
        if not feed.stop(stall_s, limit_s):
            self.on_note(
                unfinished_note(
                    "the campaign panel stopped unfinished; campaign.rrd may be cut", stall_s, limit_s
                )
            )

    # -- the view thread's side -----------------------------------------------------------------------

    def _flush(self) -> None:
        rec, self._rec = self._rec, None
        if rec is None:
            return
        try:
            rec.flush(timeout_sec=5.0)
        except RuntimeError as exc:
            self.on_note(f"the campaign panel could not be finished ({exc})")
        finally:
            with contextlib.suppress(Exception):
                rec.disconnect()

    def _log_matrix(self) -> None:
        rec = self._rec
        if rec is None:
            return
        keys = list(self._status)
        positions = [(self.angles_deg.index(a), self.drafts.index(d)) for d, a in keys]
        labels = [
            f"{d} {a:g} deg: {s}{' ' + lab if lab else ''}" for (d, a), (s, lab) in self._status.items()
        ]
        colors = [STATUS_COLORS[s] for s, _ in self._status.values()]
        rec.log(
            "campaign/matrix",
            rr.Points2D(positions, radii=0.3, colors=colors, labels=labels, show_labels=True),
            static=True,
        )

    def _series_style(self, rec: rr.RecordingStream, entity: str, draft: str, name: str) -> None:
        if entity in self._styled:
            return
        color = DRAFT_COLORS[self.drafts.index(draft) % len(DRAFT_COLORS)]
        rec.log(entity, rr.SeriesPoints(colors=[color], names=[name], marker_sizes=[5.0]), static=True)
        self._styled.add(entity)

    def _log_condition(
        self, draft: str, angle_deg: float, coefficients: Mapping[str, float], b_eq_per_s: float
    ) -> None:
        rec = self._rec
        if rec is None:
            return
        rec.set_time(ANGLE_TIMELINE, sequence=round(angle_deg))
        for term, value in coefficients.items():
            entity = f"campaign/coefficients/{term}/{draft}"
            self._series_style(rec, entity, draft, f"{term} at {draft}")
            rec.log(entity, rr.Scalars(float(value)))
        entity = f"campaign/b_eq/{draft}"
        self._series_style(rec, entity, draft, f"B_eq at {draft}")
        rec.log(entity, rr.Scalars(float(b_eq_per_s)))
