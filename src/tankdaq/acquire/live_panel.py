"""The operator's panel of the web view (``--viewer web``): what the terminal says, for the person at the
model. The target angle against the angle now (large), what to do (tilt, hold, hands off, wait for the
verdict), the last decay's verdict with its reason, and what comes next; in a guided session the
condition and the step (n of N).

A sink of the pipeline: it hears every block (the angle now, between decays too) and the typed events
(held, released, settled; a session's ``SessionStep`` and ``SessionVerdict``), and hands the view a
markdown page (``WebLiveView.log_panel``) when it changes, the angle at most ``REFRESH_S`` apart.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from ..device.driver import StreamBlock
from ..samples import AXIS_FIELDS
from ..viz.web_viewer import WebAddress, WebServer, qr_text, settle_bind
from .decay import LiveDecay
from .events import (
    Event,
    Held,
    PutBack,
    Released,
    SessionStep,
    SessionVerdict,
    Settled,
    ViewerAddress,
    ViewerNote,
)
from .sinks import Said, Sink

#: The angle now is redrawn at most this often (device seconds): a screen read at arm's length.
REFRESH_S = 0.25


def open_web_viewer(
    bind: str | None, grpc_port: int, web_port: int, emit: Callable[[Event], None]
) -> WebServer:
    """The recorder's web viewer server, started before the device opens (a port in use is one line
    then), and its address for a tablet said with its QR code (``ViewerAddress``)."""
    address = WebAddress(settle_bind(bind, lambda line: emit(ViewerNote(line))), grpc_port, web_port)
    server = WebServer(address).start()
    emit(ViewerAddress(address.tablet_url, qr_text(address.tablet_url)))
    return server


class PanelView(Protocol):
    """What the panel draws on: a web view (``WebLiveView``, or ``ViewProcess`` in web mode)."""

    def log_panel(self, markdown: str, t_s: float) -> None: ...


class LivePanel(Sink):
    """The panel's state from the pipeline's blocks and events; ``target_deg``: the nominal release
    angle (a session's ``SessionStep`` sets each decay's)."""

    def __init__(self, view: PanelView, axis: str, target_deg: float) -> None:
        self.view = view
        self.field = AXIS_FIELDS["roll" if axis == "auto" else axis][0]
        self.target_deg = target_deg
        self.heading = "Recording"
        self.prompt = f"Tilt to {target_deg:g}° and hold, then release"
        self.last = ""
        self.angle_deg = math.nan
        self.t_s = math.nan
        self._shown = ""
        self._shown_t = -math.inf

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> Said:
        samples = block.samples
        if samples.size:
            self.angle_deg = float(np.degrees(samples[self.field][-1]))
            self.t_s = float(samples["t"][-1])
            if self.t_s - self._shown_t >= REFRESH_S:
                self._show()
        return None

    def on_event(self, event: Event) -> None:
        if isinstance(event, SessionStep):
            self.target_deg = event.target_deg
            self.heading = (
                f"Step {event.step} of {event.steps} · decay {event.decay}\n\n"
                f"**{event.condition}**, repeat {event.repeat}/{event.repeats}"
            )
            self.prompt = f"Tilt to {event.target_deg:g}° and hold, then release"
        elif isinstance(event, SessionVerdict):
            self.last = _verdict(event)
            self.prompt = (
                "Answer at the PC (accept or repeat)" if event.verdict is None else f"Next: {event.next}"
            )
        elif isinstance(event, Held):
            self.prompt = f"Held at {abs(event.angle_deg):.1f}°: release when still"
        elif isinstance(event, PutBack):
            self.prompt = f"Put back: tilt to {self.target_deg:g}° again"
        elif isinstance(event, Released):
            self.prompt = f"Released at {abs(event.angle_deg):.1f}°: hands off, free decay"
        elif isinstance(event, Settled):
            outcome = event.outcome
            self.last = f"Decay {outcome.run}: {outcome.ended.value}" + (
                f", warnings: {'; '.join(outcome.warnings)}" if outcome.warnings else ""
            )
            self.prompt = f"Settled: tilt to {self.target_deg:g}° for the next decay"
        else:
            return
        self._show(force=True)

    def markdown(self) -> str:
        """The page: heading, the angle now against the target (large), the prompt (what comes next), the
        last decay."""
        now = "—" if math.isnan(self.angle_deg) else f"{self.angle_deg:+.1f}°"
        lines = [
            self.heading,
            f"# {now} → target {self.target_deg:g}°",
            f"## {self.prompt}",
            *_optional("Last", self.last),
        ]
        return "\n\n".join(lines)

    def _show(self, force: bool = False) -> None:
        if math.isnan(self.t_s):
            return
        page = self.markdown()
        if page != self._shown or force:
            self.view.log_panel(page, self.t_s)
            self._shown = page
        self._shown_t = self.t_s


def _optional(label: str, text: str) -> Sequence[str]:
    return [f"**{label}:** {text}"] if text else []


def _verdict(event: SessionVerdict) -> str:
    why = "; ".join(event.reasons) or "every check passed"
    return f"decay {event.decay} **{event.said.upper()}** — {why}"
