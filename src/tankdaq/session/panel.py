"""The campaign panel of a guided session (``viz.campaign_view``): the test matrix with each condition's
status, and the mean model of each condition once its repeats are accepted.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..config.hulls import format_draft, parse_draft
from ..config.plans import CampaignPlan
from .checks import Measured
from .plan import PlannedCondition
from .state import SessionState

if TYPE_CHECKING:
    from ..acquire.daemon import RecordSettings
    from ..viz.campaign_view import CampaignView

PANEL_NAME = "campaign.rrd"


def open_panel(record: RecordSettings, plan: CampaignPlan, on_note: Callable[[str], None]) -> CampaignView:
    """The panel, beside the decay views: a spawned viewer is started first, so it listens before the
    first decay and the decay views reuse it."""
    from ..physics.models import resolve_model
    from ..viz.campaign_view import CampaignView
    from ..viz.viewer import DEFAULT_BIND, default_viewer_mode, display_available, spawn_viewer

    mode = record.viewer or default_viewer_mode()
    url = None
    if mode == "spawn" and display_available():  # without a display each decay's view says so, once
        bind = record.viewer_bind or DEFAULT_BIND
        _process, url = spawn_viewer(bind, record.viewer_port, on_note)  # it outlives us
    return CampaignView(
        mode,
        record.out_dir / PANEL_NAME,
        [format_draft(parse_draft(d)) for d in plan.drafts],
        plan.angles_deg,
        resolve_model(record.model),
        viewer_url=url,
        on_note=on_note,
    )


def show_condition(view: CampaignView, state: SessionState, condition: PlannedCondition) -> None:
    """The condition's status and kept repeats; once accepted, its mean model and B_eq."""
    kept = len(state.accepted(condition))
    status = state.status(condition)
    view.set_status(condition.draft, condition.angle_deg, status, f"{kept}/{state.repeats}")
    if status == "accepted":
        measured = [Measured.from_log(r.measured) for r in state.accepted(condition)]
        terms = dict.fromkeys(k for m in measured for k in m.coefficients)  # repeats' models may differ:
        mean = {k: float(np.mean([m.coefficients.get(k, 0.0) for m in measured])) for k in terms}  # absent 0
        view.accepted(
            condition.draft, condition.angle_deg, mean, float(np.mean([m.b_eq_per_s for m in measured]))
        )
