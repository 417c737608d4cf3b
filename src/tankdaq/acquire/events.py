"""What the record pipeline tells its listeners, as typed events: a release, a settle, a warning, the
device gone and back, the stop.

The pipeline, the daemon and replay emit these; every listener hears them through ``Sink.on_event``
(``acquire.sinks``): the command line's printer, a guided session, a notebook's collector
(``acquire.listeners``). Nothing downstream reads the words: each event carries its values, and
``line()`` renders the one line a person reads (``run_name`` relabels the run, e.g. a guided
session's "decay 5"); ``record()`` is the event as a JSON object (``--events jsonl``).
"""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, fields
from enum import StrEnum
from pathlib import Path
from typing import ClassVar

from ..live.identifier import OnlineResult
from ..records import DecayEnd, Verdict
from ..samples import StatusTally

#: How a recorded decay can end (``Settled``'s ``outcome.ended``), as the printed legend explains it. Only
#: the first two are whole; the others are partial: their file is complete with what arrived, and they are
#: left out of campaigns unless asked for.
SETTLE_REASONS = {
    DecayEnd.SETTLED: "the swing fell below the settle threshold (a whole decay)",
    DecayEnd.TIMEOUT: "the decay went on to the longest a decay may last (a whole decay)",
    DecayEnd.STOPPED: "stopped by the operator: Ctrl-C, SIGTERM or a closed terminal (partial)",
    DecayEnd.STREAM_ENDED: "the stream or the replayed file ended mid-decay (partial)",
    DecayEnd.DEVICE_LOST: "the device went away mid-decay (partial)",
    DecayEnd.ERROR: "closed after an error (partial; the error is in the file)",
}


@dataclass
class DecayOutcome:
    """What one recorded decay left behind."""

    run: int
    axis: str
    path: Path | None
    rrd_path: Path | None
    release_t: float
    angle_initial_deg: float
    ended: DecayEnd
    fit: OnlineResult | None
    warnings: list[str]
    status: StatusTally | None = None  # the status flags of its samples (clipping before and after release)
    last_t: float = math.nan  # device time of its last sample
    release_u95_s: float = math.nan  # half-width of the release instant's 95 % interval (NaN: unknown)

    @property
    def ended_after_s(self) -> float:
        """Device seconds recorded after the release (nan when unknown)."""
        return self.last_t - self.release_t


#: The outcomes a pipeline or daemon keeps, newest last. Each is 2-4 kB, so keeping all of a lab day's
#: would grow the recorder by megabytes. Every outcome is also a ``Settled`` event
#: for every listener and, once recorded, a file and a catalogue row.
KEPT_OUTCOMES = 100


class KeptOutcomes:
    """The newest ``KEPT_OUTCOMES`` decays' outcomes (iterated oldest first) and ``count``, how many
    decays there were in all: what a day-long recorder keeps without growing."""

    def __init__(self) -> None:
        self._recent: deque[DecayOutcome] = deque(maxlen=KEPT_OUTCOMES)
        self.count = 0

    def append(self, outcome: DecayOutcome) -> None:
        self._recent.append(outcome)
        self.count += 1

    def extend(self, outcomes: Iterable[DecayOutcome]) -> None:
        for outcome in outcomes:
            self.append(outcome)

    def __iter__(self) -> Iterator[DecayOutcome]:
        return iter(self._recent)

    def __len__(self) -> int:
        """How many are kept (at most ``KEPT_OUTCOMES``); ``count`` is how many there were."""
        return len(self._recent)


class Event:
    """One thing that happened. ``printed`` False: a listener's event, not a line for the terminal;
    ``streamed`` False: kept with the decay (its file, its view), not a program's event either."""

    printed: ClassVar[bool] = True
    streamed: ClassVar[bool] = True

    def line(self, run_name: str | None = None) -> str:
        """The line a person reads (``run_name`` replaces "run N" where the event names a run)."""
        raise NotImplementedError

    def record(self) -> dict[str, object]:
        """The event as a JSON object: ``event`` names its type, the rest are its values."""
        values = {f.name: _jsonable(getattr(self, f.name)) for f in fields(self)}  # type: ignore[arg-type]
        return {"event": _snake(type(self).__name__), **values}


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)([A-Z])", r"_\1", name).lower()


def _jsonable(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def _run(run: int | None, run_name: str | None) -> str:
    return run_name or f"run {run}"


@dataclass(frozen=True)
class Notice(Event):
    """A one-line notice from a part around the pipeline: ``source`` is device (the port, the simulator,
    the orientation the device gives), identifier (its kernels), recording (a file) or replay."""

    source: str
    text: str

    def line(self, run_name: str | None = None) -> str:
        return self.text


@dataclass(frozen=True)
class ViewerNote(Event):
    """What the live view says: the mode in use, a viewer started, a dropped update."""

    text: str

    def line(self, run_name: str | None = None) -> str:
        return f"viewer: {self.text}"


@dataclass(frozen=True)
class ViewerAddress(Event):
    """The web viewer listens (``--viewer web``): ``url`` is what a tablet or phone opens, ``qr`` its QR
    code in terminal characters (not in the JSON record: the URL says it)."""

    url: str
    qr: str = ""

    def line(self, run_name: str | None = None) -> str:
        qr = f"\n{self.qr}" if self.qr else ""
        return f"viewer: open {self.url} on a tablet or phone (same network; view only){qr}"

    def record(self) -> dict[str, object]:
        return {"event": "viewer_address", "url": self.url}


@dataclass(frozen=True)
class DeviceReady(Event):
    """The device is open and configured (``description``: product, firmware, serial, port, rate)."""

    description: str

    def line(self, run_name: str | None = None) -> str:
        return f"device: {self.description}"


@dataclass(frozen=True)
class Held(Event):
    """The model is held tilted (signed, from the still water)."""

    angle_deg: float
    axis: str

    def line(self, run_name: str | None = None) -> str:
        return f"held at {self.angle_deg:+.2f} deg ({self.axis})"


@dataclass(frozen=True)
class PutBack(Event):
    """The model was held, then put back without a release."""

    def line(self, run_name: str | None = None) -> str:
        return "put back without a release"


@dataclass(frozen=True)
class Released(Event):
    """A confirmed release: run ``run`` starts (``t_s``: device time of the release, ``u95_s`` the half-width
    of its 95 % interval; NaN: unknown, and said so)."""

    run: int
    angle_deg: float  # signed, from the still water
    axis: str
    t_s: float
    u95_s: float = math.nan

    def line(self, run_name: str | None = None) -> str:
        where = _run(self.run, run_name)
        when = said_instant(self.t_s, self.u95_s)
        return f"{where}: released at {abs(self.angle_deg):.2f} deg ({self.axis}), t = {when}"


def said_instant(t_s: float, u95_s: float) -> str:
    """A release instant as people read it: with its 95 % interval in ms, or saying that it is unknown."""
    if math.isfinite(u95_s):
        return f"{t_s:.4f} s ± {1e3 * u95_s:.1f} ms (95 %)"
    return f"{t_s:.3f} s (interval unknown)"


class NoteKind(StrEnum):
    """What a note of a decay is: the file's event kind and the word its printed line starts with."""

    WARNING = "warning"  # the decay or its fit may be wrong
    NOTE = "note"  # worth knowing, not a fault
    UNPLUG = "unplug"  # the device went away mid-decay (kept with the decay; the person hears ``DeviceLost``)


@dataclass(frozen=True)
class Note(Event):
    """A note of a decay: ``kind`` warning (the decay or its fit may be wrong) or note (worth knowing,
    not a fault); ``run`` None: said at the release, before the run is named. The decay's file and view
    keep it at device time ``t_s`` (None: when it is said) with ``data``."""

    kind: NoteKind
    text: str
    run: int | None = None
    t_s: float | None = None
    data: Mapping[str, object] | None = None

    def line(self, run_name: str | None = None) -> str:
        where = "" if self.run is None and run_name is None else f"{_run(self.run, run_name)}: "
        return f"{self.kind}: {where}{self.text}"

    def record(self) -> dict[str, object]:
        return {"event": "note", "kind": self.kind, "text": self.text, "run": self.run}


@dataclass(frozen=True)
class KeptNote(Note):
    """A note the decay's file and view keep that a person was told another way (``Stopping``,
    ``DeviceLost``, the error raised): neither printed nor streamed."""

    printed: ClassVar[bool] = False
    streamed: ClassVar[bool] = False


@dataclass(frozen=True)
class Fitted(Event):
    """A refit (or, ``final``, the final fit: the decay's verdict) of run ``run``: for the decay's file and
    view and for listeners (a notebook's live table), not printed."""

    printed: ClassVar[bool] = False
    run: int
    result: OnlineResult
    final: bool = False

    def line(self, run_name: str | None = None) -> str:
        r = self.result
        return f"{_run(self.run, run_name)}: fit to {r.t_end:.2f} s, R2 {r.r2_angle:.4f}"

    def record(self) -> dict[str, object]:
        r = self.result
        return {
            "event": "fitted",
            "run": self.run,
            "t_end_s": r.t_end,
            "coefficients": dict(r.coefficients),
            "r2_angle": _jsonable(r.r2_angle),
        }


#: A decay's final live fit over fewer half-cycles than this (a run stopped or unplugged within a cycle or
#: so of its release) is said to be no result where its line shows it.
FEW_HALF_CYCLES = 4


@dataclass(frozen=True)
class Settled(Event):
    """Run ``outcome.run`` ended (``outcome.ended``, see ``SETTLE_REASONS``), its file closed; the line
    says how in plain words, and a partial decay says so."""

    outcome: DecayOutcome

    def line(self, run_name: str | None = None) -> str:
        outcome = self.outcome
        fit = outcome.fit
        coeffs = "  ".join(f"{k}={v:.4g}" for k, v in fit.coefficients.items()) if fit else "no fit"
        where = f" -> {outcome.path}" if outcome.path else ""
        period = f", T0 {fit.natural_period_s:.3f} s, R2 {fit.r2_angle:.4f}" if fit else ""
        status = outcome.status
        said = (status.describe_after(), status.describe_before()) if status else ()
        flags = "".join(f"; {line}" for line in said if line)
        if fit and fit.half_cycles < FEW_HALF_CYCLES:  # a run stopped early: its live fit is no result
            flags += (
                f"; a live fit over {fit.half_cycles} half-cycle(s) only: fit the file with tankdaq identify"
            )
        ended = outcome.ended.said(outcome.ended_after_s)
        return f"{_run(outcome.run, run_name)}: {ended}; {coeffs}{period}{flags}{where}"

    def record(self) -> dict[str, object]:
        o = self.outcome
        fit = o.fit
        return {
            "event": "settled",
            "run": o.run,
            "axis": o.axis,
            "ended": o.ended.value,
            "whole": o.ended.whole,
            "ended_after_s": _jsonable(o.ended_after_s),
            "path": _jsonable(o.path),
            "release_t_s": o.release_t,
            "release_u95_s": _jsonable(o.release_u95_s),
            "angle_initial_deg": o.angle_initial_deg,
            "coefficients": dict(fit.coefficients) if fit else None,
            "natural_period_s": _jsonable(fit.natural_period_s) if fit else None,
            "r2_angle": _jsonable(fit.r2_angle) if fit else None,
            "warnings": list(o.warnings),
        }


@dataclass(frozen=True)
class DeviceLost(Event):
    """The device went away (``reason``); the daemon waits ``wait_s`` for it to come back."""

    reason: str
    wait_s: float

    def line(self, run_name: str | None = None) -> str:
        return f"device gone ({self.reason}); waiting up to {self.wait_s:g} s"


@dataclass(frozen=True)
class DeviceBack(Event):
    """The device came back after ``after_s`` and streams again."""

    after_s: float

    def line(self, run_name: str | None = None) -> str:
        return f"device back after {self.after_s:.1f} s"


@dataclass(frozen=True)
class Stopping(Event):
    """A signal (``signal``: SIGINT, SIGTERM, SIGHUP) stops the recording: the files are being closed."""

    signal: str

    def line(self, run_name: str | None = None) -> str:
        return f"stopping ({self.signal}): closing files"


@dataclass(frozen=True)
class Stopped(Event):
    """The stream ended: ``by`` the signal that stopped it, None when every decay asked for was recorded
    (or the orchestrator ended it). Not printed: the command says what was recorded."""

    printed: ClassVar[bool] = False
    by: str | None
    decays: int

    def line(self, run_name: str | None = None) -> str:
        how = f"stopped by {self.by}" if self.by else "ended"
        return f"recording {how}: {self.decays} decay(s)"


class MovedKind(StrEnum):
    """What the guided session's watch between decays reports (``ModelMoved.kind``)."""

    DRIFT = "drift"
    BUMP = "bump"
    LEVEL = "level"
    TREND = "trend"


#: Each ``MovedKind`` as the printed legend says it.
MOVED_KINDS = {
    MovedKind.DRIFT: "its still water moved away from the level measured when the draft was set",
    MovedKind.BUMP: "it moved for a moment while it should have been at rest (not a release)",
    MovedKind.LEVEL: "it rests off level before the next decay",
    MovedKind.TREND: (
        "its still water creeps (a slope of its level over the last seconds at rest) before it drifts"
    ),
}


@dataclass(frozen=True)
class ModelMoved(Event):
    """Between decays the model did not rest as it should (a guided session's watch, ``kind`` one of
    ``MOVED_KINDS``): over the window starting at device time ``t_s``, the angle's mean ``angle_deg``
    and spread ``spread_deg``, the rate of turn's ``rate_deg_s`` (rms about its mean); ``reference_deg``
    the still water measured when the draft was set; ``limit_deg`` the tolerance it broke (the plan's
    level tolerance for drift, level and a trend, the still-water spread for a bump); a trend's
    ``slope_deg_min``, how fast the still water creeps (nan for the others)."""

    kind: MovedKind
    angle_deg: float
    spread_deg: float
    rate_deg_s: float
    reference_deg: float
    limit_deg: float
    t_s: float
    slope_deg_min: float = math.nan

    def line(self, run_name: str | None = None) -> str:
        if self.kind == MovedKind.DRIFT:
            moved = self.angle_deg - self.reference_deg
            return (
                f"drift: still water at {self.angle_deg:+.2f} deg, {moved:+.2f} deg from the "
                f"{self.reference_deg:+.2f} measured when the draft was set "
                f"(tolerance {self.limit_deg:g} deg); re-trim before the next decay"
            )
        if self.kind == MovedKind.TREND:
            moved = self.angle_deg - self.reference_deg
            left_deg = self.limit_deg - moved * math.copysign(1.0, self.slope_deg_min)  # the way it creeps
            when = (
                f"at this rate it passes the {self.limit_deg:g} deg tolerance in about "
                f"{60 * left_deg / abs(self.slope_deg_min):.0f} s"
                if left_deg > 0
                else f"already past the {self.limit_deg:g} deg tolerance"
            )
            return (
                f"trend: still water creeping at {self.slope_deg_min:+.1f} deg/min, now "
                f"{self.angle_deg:+.2f} deg, {moved:+.2f} deg from the {self.reference_deg:+.2f} measured "
                f"when the draft was set; {when}; look for water inside or a weight that moved"
            )
        if self.kind == MovedKind.BUMP:
            return (
                f"bump: the model moved at rest (spread {self.spread_deg:.2f} deg, "
                f"rate {self.rate_deg_s:.1f} deg/s rms; at rest it stays under {self.limit_deg:g} deg); "
                "let it settle before the tilt"
            )
        return (
            f"level: still water at {self.angle_deg:+.2f} deg, off level (tolerance {self.limit_deg:g} deg); "
            "re-trim before the next decay"
        )


def legend(event: Event) -> str | None:
    """The words an event's line uses that need explaining, said once before the first such line."""
    if isinstance(event, Settled):
        reasons = "; ".join(f"{end.value} = {why}" for end, why in SETTLE_REASONS.items())
        return (
            f"(each run's line: RUN: how it ended (a partial decay says so); the live fit's coefficients, T0 "
            f"and R2; the file. How a run ends, as the file and the catalogue name it: {reasons})"
        )
    if isinstance(event, Note):
        return "(warning: the decay or its fit may be wrong, check it; note: worth knowing, not a fault)"
    if isinstance(event, ModelMoved):
        kinds = "; ".join(f"{name} = {why}" for name, why in MOVED_KINDS.items())
        return f"(between decays the session watches the model at rest: {kinds})"
    return None


@dataclass(frozen=True)
class SessionStep(Event):
    """A guided session asks for its next decay (the operator's panel on the tablet shows it; the terminal
    has its own line): decay ``decay``, the ``step``-th of the ``steps`` decays the plan keeps, of
    ``condition`` at ``target_deg``, repeat ``repeat`` of ``repeats``."""

    printed: ClassVar[bool] = False
    decay: int
    step: int
    steps: int
    condition: str
    target_deg: float
    repeat: int
    repeats: int

    def line(self, run_name: str | None = None) -> str:
        return (
            f"decay {self.decay}, step {self.step} of {self.steps}: {self.condition}, repeat "
            f"{self.repeat}/{self.repeats}: tilt to {self.target_deg:g} deg and release"
        )


@dataclass(frozen=True)
class SessionVerdict(Event):
    """A guided session's decay checked: ``verdict`` None while the operator is asked at the PC, then what
    they said; the checks' ``reasons`` against it and what comes ``next``."""

    printed: ClassVar[bool] = False
    decay: int
    verdict: Verdict | None
    reasons: tuple[str, ...]
    next: str

    @property
    def said(self) -> str:
        """The verdict in words: accepted, rejected, or to judge."""
        return "to judge" if self.verdict is None else self.verdict.value

    def line(self, run_name: str | None = None) -> str:
        why = "; ".join(self.reasons) or "every check passed"
        return f"decay {self.decay}: {self.said} ({why}); next: {self.next}"
