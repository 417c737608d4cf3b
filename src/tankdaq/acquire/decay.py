"""The decay under way as the pipeline and its sinks share it, and the live fit of it.

``LiveDecay`` is a record: the pipeline fills in the release and how it ended, sinks fill in what they made
(``path`` by the file, ``rrd_path`` by the view). It holds no way back into the pipeline: what happens to
a decay reaches the sinks only as the pipeline's typed events (``acquire.events``).

``LiveFit`` is a stage of the pipeline, as the release detector is, not a sink: it is handed the decay's
samples and returns what it has to say (``Fitted``, and a ``Note`` for a fit physics finds implausible or
a refit abandoned), which the pipeline broadcasts once the sinks have heard the block (python-can's
``Notifier``: one producer, one fan-out). The final fit is asked for before any sink hears the settle, so
the file holds it when it closes, whatever the order of the sinks.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..device.driver import StreamBlock
from ..errors import TankdaqError
from ..live.identifier import OnlineIdentifier, OnlineResult
from ..live.worker import REFIT_BUDGET_S, BackgroundFit
from ..records import DecayEnd
from ..samples import AXIS_FIELDS, StatusTally
from .events import DecayOutcome, Event, Fitted, Note, NoteKind

if TYPE_CHECKING:
    from .release import ReleaseEvent

#: How long the final fit at settle may compute (CPU time on its worker; it normally takes well under
#: 0.1 s once the kernels are prepared); past it, or past ``FINAL_FIT_WALL_FACTOR`` times it on the wall
#: clock, the file is closed without it and says so.
FINAL_FIT_WAIT_S = 5.0


@dataclass
class LiveDecay:
    """The decay under way, as the pipeline and its sinks share it.

    The pipeline fills in the release, the fits it broadcast (``fit``, ``final_fit``) and ``warnings``;
    sinks fill in what they made (``path`` by the file, ``rrd_path`` by the view). ``ended`` is set at
    the end (``ERROR``: closed after an exception, with ``error`` saying which).
    """

    run: int
    axis: str
    terms: tuple[str, ...]
    release_t: float
    angle_deg: float  # measured initial angle from the still water (signed)
    release_event: ReleaseEvent
    warnings: list[str]
    last_t: float = math.nan
    path: Path | None = None
    rrd_path: Path | None = None
    fit: OnlineResult | None = None  # the latest fit broadcast
    final_fit: OnlineResult | None = None
    final_fit_s: float = math.nan
    ended: DecayEnd | None = None  # None while it runs
    error: str = ""
    model: str = ""  # the live model as asked ("auto": chosen by the data); ``terms`` is what it may use
    status: StatusTally = field(init=False)  # the status flags counted as samples arrive (the session's)

    def __post_init__(self) -> None:
        self.status = StatusTally(self.release_t)

    def heard(self, event: Event) -> None:
        """What the decay keeps of an event the pipeline broadcasts about it: its fits and warnings (those
        said at the release, before the run is named, it was made with)."""
        if isinstance(event, Fitted) and event.run == self.run:
            self.fit = event.result
            if event.final:
                self.final_fit = event.result
        elif isinstance(event, Note) and event.run == self.run and event.kind == NoteKind.WARNING:
            self.warnings.append(event.text)

    @property
    def release_message(self) -> str:
        return f"released at {abs(self.angle_deg):.3f} deg"

    def release_data(self) -> dict[str, object]:
        """The release event's data (degrees at this edge)."""
        ev = self.release_event
        return {
            "angle_initial_deg": self.angle_deg,
            "rate_initial_deg_s": math.degrees(ev.rate_rad_s) if math.isfinite(ev.rate_rad_s) else None,
            "still_water_deg": math.degrees(ev.baseline_rad),
            "first_free_sample_t_s": ev.t,
            "release_se_s": ev.release_se_s if math.isfinite(ev.release_se_s) else None,
            "release_u95_s": ev.release_u95_s if math.isfinite(ev.release_u95_s) else None,
        }

    def settle_metadata(self) -> dict[str, object]:
        """What the recording's metadata gains at close: how it ended (``ended``) and the final fit."""
        if self.ended is DecayEnd.ERROR:
            return {"ended": self.ended.value, "error": self.error, **self.status.metadata()}
        extra: dict[str, object] = {
            "ended": self.ended_value,
            "final_fit_s": self.final_fit_s,
            **self.status.metadata(),
        }
        final = self.final_fit
        if final is not None:
            extra.update({f"fit_{k}": v for k, v in final.coefficients.items()})
            extra["fit_r2_angle"] = final.r2_angle
            extra["natural_period_s"] = final.natural_period_s
        return extra

    def outcome(self) -> DecayOutcome:
        """What the decay leaves once it is over: its fit's numbers without the predicted curve (a run
        keeps every outcome: with a curve each, a day of decays at 400 Hz kept about 9 MB an hour)."""
        fit = self.final_fit if self.ended is not DecayEnd.ERROR else self.fit
        return DecayOutcome(
            run=self.run,
            axis=self.axis,
            path=self.path,
            rrd_path=self.rrd_path,
            release_t=self.release_t,
            release_u95_s=self.release_event.release_u95_s,
            angle_initial_deg=self.angle_deg,
            ended=self.ended_value,
            fit=None if fit is None else fit.without_curve(),
            warnings=list(self.warnings),
            status=self.status,
            last_t=self.last_t,
        )

    @property
    def ended_value(self) -> DecayEnd:
        """How it ended, once it has (the pipeline sets ``ended`` before any sink hears the settle)."""
        assert self.ended is not None, "the decay has not ended"
        return self.ended


class LiveFit:
    """The online identifier as a stage of the pipeline: samples after the release go to its worker
    thread; what it finds comes back as events for the pipeline to broadcast.

    ``wait_for_fits`` (replay): each block's refit is done before the next block (the same refits
    every replay); live, a block only hands samples over and finished refits come back at the next
    block. At settle the final fit waits at most ``FINAL_FIT_WAIT_S``. A refit past
    ``refit_budget_s`` is abandoned on the worker (the loop never waits on it) and a warning says so.
    """

    def __init__(
        self,
        identifier: Callable[..., OnlineIdentifier] = OnlineIdentifier,
        wait_for_fits: bool = False,
        refit_budget_s: float = REFIT_BUDGET_S,
    ) -> None:
        self.make_identifier = identifier  # called as identifier(terms, axis=...) at each release
        self.wait_for_fits = wait_for_fits
        self.refit_budget_s = refit_budget_s  # a live refit past it is abandoned (a warning event)
        self._live: BackgroundFit | None = None
        self._implausible: list[str] = []  # the checks the latest fit failed: each said once in a row

    def start(self, decay: LiveDecay, pretrigger: Sequence[StreamBlock]) -> None:
        """A new identifier for the decay released, fed the blocks since the pre-trigger."""
        identifier = self.make_identifier(decay.model or decay.terms, axis=decay.axis)
        self._live = BackgroundFit(identifier, refit_budget_s=self.refit_budget_s)
        self._implausible = []
        for block in pretrigger:
            self._submit(block, decay)

    def feed(self, block: StreamBlock, decay: LiveDecay) -> list[Event]:
        """The block's samples handed over; the refits finished since, and what they say."""
        if self._live is None:
            return []
        self._submit(block, decay)
        if self.wait_for_fits:
            self._live.wait_idle(FINAL_FIT_WAIT_S)
        said: list[Event] = []
        for result in self._live.take():
            said += self._said(decay, result)
        return said + self._abandoned(self._live, decay)

    def finish(self, decay: LiveDecay, until_t: float = math.inf) -> list[Event]:
        """The decay ended: the last refits and the final fit of its samples up to ``until_t`` (the device
        time its end was decided; none after an error: it may be in it)."""
        live, self._live = self._live, None
        if live is None:
            return []
        if decay.ended is DecayEnd.ERROR:
            live.close()
            return []
        started = time.perf_counter()
        try:
            refits, final = live.finish(FINAL_FIT_WAIT_S, until_t)
        except TankdaqError as exc:  # an unfittable decay (too short, cut by an unplug) is a warning
            return [*self._abandoned(live, decay), Note(NoteKind.WARNING, f"no final fit: {exc}", decay.run)]
        finally:
            decay.final_fit_s = time.perf_counter() - started
        said: list[Event] = []
        for result in refits:
            said += self._said(decay, result)
        said += self._abandoned(live, decay)
        self._implausible = []  # the final fit's implausibilities are said again: they are the verdict's
        return said + self._said(decay, final, final=True)

    def _said(self, decay: LiveDecay, result: OnlineResult, final: bool = False) -> list[Event]:
        """The fit, then an implausibility it carries (a check the last fit passed) as a warning: the
        file's events, the view's event log, the record lines."""
        about_fit = [f for f in result.findings if not f.about_data]  # the data's flags: the session's note
        new = [f for f in about_fit if f.check not in self._implausible]
        self._implausible = [finding.check for finding in about_fit]
        at = result.t_end - decay.release_t
        warnings = [Note(NoteKind.WARNING, f"fit at {at:.1f} s: {f}", decay.run, result.t_end) for f in new]
        return [Fitted(decay.run, result, final), *warnings]

    @staticmethod
    def _abandoned(live: BackgroundFit, decay: LiveDecay) -> list[Event]:
        """A refit past its budget was abandoned on the worker: the record says so (a warning)."""
        return [Note(NoteKind.WARNING, line, decay.run) for line in live.take_notes()]

    def _submit(self, block: StreamBlock, decay: LiveDecay) -> None:
        assert self._live is not None
        after = block.samples[block.samples["t"] >= decay.release_t] if block.samples.size else block.samples
        if after.size:
            angle_field, rate_field = AXIS_FIELDS[decay.axis]
            excluded = decay.status.unusable(after)
            self._live.submit(
                after["t"].copy(), after[angle_field].copy(), after[rate_field].copy(), excluded
            )

    def close(self) -> None:
        live, self._live = self._live, None
        if live is not None:
            live.close()
