"""The loop of a guided test session (``GuidedSession``): the campaign plan drives the recording,
condition by condition.

The plan (``guided.plan``) gives the conditions in order, drafts grouped (ballast changes are slow).
The device is opened once and streams for the whole session (``acquire.streaming.SessionStream``: a
``Recorder`` as ``record`` has, the same pipeline, sinks and signal handling): the session is one more
listener of it and moves through its plan on its typed events. For each condition the operator is told
what to do and the session feeds the stream until that decay settles (on port ``sim`` the simulated
sensor plays the decay asked for); the still water before a draft's first decay is measured from the
same stream (``LevelCheck``), and from then on the model is watched between decays (``guided.watch``: drift, a
bump, level, each a typed ``ModelMoved``). The decay is measured (``guided.measure``) and checked
(``guided.checks``, with what the watch saw standing at its release) as soon as it settles, and the
operator (``guided.operator``) accepts it, repeats it, skips the condition or adds a note. Every
question is asked on a thread of its own while the session's thread feeds the stream
(``SessionStream.stream_during``): a long pause piles nothing up, and a decay released while nobody
asked for one is recorded, then kept and logged as rejected (``guided.recovery``). When every condition
has its repeats, the device is closed and the report of the accepted decays written (``guided.report``).
The session hears each recording as typed events (``acquire.events``): it prints them with its decay
numbers, and a Ctrl-C, SIGTERM or SIGHUP, in a decay or at a question (``Stopped``), ends ``run`` with
``stopped`` set, every file closed, never by an exception.

Everything that happens goes to ``session.jsonl`` under a lock (``guided.journal``), fsynced before the
session goes on. The session's state is only ever derived from that file (``guided.state``), so
``resume`` after Ctrl-C, a crash or a power cut continues exactly where it stopped: a decay recorded
but not yet judged is judged first, and a recording the log never heard of (the session died
mid-decay) is logged as rejected, never lost.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..acquire.daemon import RecordSettings
from ..acquire.events import (
    DecayOutcome,
    DeviceReady,
    Event,
    ModelMoved,
    Notice,
    SessionStep,
    SessionVerdict,
    Settled,
    Stopped,
    ViewerAddress,
    ViewerNote,
)
from ..acquire.listeners import EventLog, EventPrinter
from ..acquire.sinks import Sink
from ..acquire.streaming import SessionStream
from ..config.hulls import load_hull
from ..config.plans import PLAN_AXES, CampaignPlan
from ..config.rules import path_in
from ..errors import InputError
from ..records import Verdict
from .checks import STILL_SD_DEG, Measured, check_decay, is_level, watch_reasons
from .journal import SessionLock, SessionLog, check_resumable
from .measure import LEVEL_S, LevelCheck, measure_decay
from .operator import Operator, Question, SessionProgress, draft_question, keys_line, verdict_question
from .panel import open_panel, show_condition
from .plan import Acceptance, PlannedCondition, plan_conditions
from .recovery import RELEASED_BETWEEN, adopt_orphans, mark_missing
from .report import REPORT_DIR, write_session_report
from .state import RunEntry, SessionState
from .watch import ModelWatch

if TYPE_CHECKING:
    from ..viz.campaign_view import CampaignView

#: events shown once in a session (the device's lines; each decay's view says the same viewer line)
SHOWN_ONCE = (Notice, DeviceReady, ViewerNote, ViewerAddress)


@dataclass
class SessionSettings:
    """A guided session: the plan, the hull, where, and how each decay is recorded."""

    plan: CampaignPlan
    hull: str
    record: dict[str, Any]  # RecordSettings of every decay (port, out_dir, rate, viewer, model, sim...)
    sim_faults: dict[int, str] = field(default_factory=dict)  # decay number -> scripted fault (port sim)


class GuidedSession:
    """``run()`` leads the operator through the plan; see the module docstring."""

    def __init__(
        self,
        settings: SessionSettings,
        operator: Operator,
        on_line: Callable[[str], None] | None = None,
        on_progress: Callable[[SessionProgress], None] | None = None,
        resume: bool = False,
        on_verdict: Callable[[RunEntry], None] | None = None,
        listeners: Sequence[Sink] = (),  # hear every recording's events (a notebook, a test)
    ) -> None:
        self.settings = settings
        self.listeners = list(listeners)
        self.on_verdict = on_verdict or (lambda _entry: None)  # after the log holds it (the run catalogue)
        self.operator = operator
        self.on_line = on_line or (lambda _line: None)
        self.on_progress = on_progress or (lambda _p: None)
        self.resume = resume
        plan = settings.plan
        if plan.axis not in PLAN_AXES:  # a plan made in code: a file's is checked as it is read
            raise InputError(
                f"plan {plan.name}: axis must be one of {', '.join(PLAN_AXES)}, not {plan.axis!r}"
            )
        first = plan_conditions(plan)[0]  # a placeholder condition: each decay gets its own
        self.record = RecordSettings(
            **{"draft": first.draft_factor, "angle_deg": first.angle_deg} | settings.record
        ).seeded()  # port sim: one seed for the session, said in every file (each decay's is seed + decay)
        self.folder = self.record.out_dir
        self.acceptance = Acceptance.from_plan(plan.acceptance, f"plan {plan.name}")
        self.conditions = plan_conditions(plan)
        hull = load_hull(settings.hull)
        if hull.name not in plan.hulls and settings.hull not in plan.hulls:
            raise InputError(
                f"plan {plan.name} covers {', '.join(plan.hulls)}, not {hull.name}; give one of them"
            )
        for condition in self.conditions:  # every condition checked before the device opens
            settings_of_decay = self._record_settings(condition, 1)
            settings_of_decay.check()
            settings_of_decay.recorded_device()
        self.log = SessionLog(self.folder)
        self._started = time.monotonic()
        self._decay_seconds: list[float] = []
        self._decay: int | None = None  # the decay being recorded: the events' run is named after it
        self.printer = EventPrinter(self.on_line, self._run_name, once=SHOWN_ONCE)
        self.view: CampaignView | None = None
        self.stopped: Stopped | None = None  # how the recording was stopped, when it was (run() returns)
        self.level = LevelCheck(plan.axis)
        self.watch = ModelWatch(plan.axis, self.acceptance.level_tolerance_deg)
        self.heard = EventLog(self._react)  # what the recorder said, typed: the session moves on its events
        self.stream: SessionStream | None = None  # opened by the first step that needs the device
        self._device = contextlib.ExitStack()

    # ---- settings of one decay ----------------------------------------

    def _record_settings(self, condition: PlannedCondition, decay: int) -> RecordSettings:
        from ..physics.scenario import scripted_run

        base = self.record
        overrides = (
            scripted_run(self.settings.sim_faults.get(decay), condition.angle_deg) | {"runs": 1}
            if base.port == "sim"
            else {}
        )  # the simulated sensor plays this one decay when the session asks for it
        return dataclasses.replace(
            base,
            hull=self.settings.hull,
            axis=self.settings.plan.axis,
            draft=condition.draft_factor,
            angle_deg=condition.angle_deg,
            angle_tolerance_deg=self.acceptance.angle_tolerance_deg,
            runs=None,  # the device streams the whole session
            sim_seed=None if base.sim_seed is None else base.sim_seed + decay,
            sim_overrides=overrides,
            note=f"session {self.settings.plan.name}, decay {decay}",
        )

    # ---- the session ----------------------------------------

    def run(self) -> SessionState:
        """Lead the session to its end (or until interrupted); returns the final state."""
        self.folder.mkdir(parents=True, exist_ok=True)
        with SessionLock(self.folder), contextlib.ExitStack() as device:
            self._device = device
            state = self._open_log()
            self._open_panel(state)
            try:
                return self._lead(state)
            finally:
                if self.view is not None:
                    self.view.close()

    def _open_stream(self) -> Stopped | None:
        """The session's one recorder: the device opened and configured before the first question, streaming
        until the session ends (``run`` closes it); a signal while it opens: the ``Stopped``."""
        first = self.conditions[0]
        settings = self._record_settings(first, 0)
        if settings.port == "sim":  # still water until the session asks for a decay
            settings = dataclasses.replace(settings, sim_overrides={"runs": 0})
        sinks = [self.level, self.watch, self.printer, self.heard, *self.listeners]
        stream = SessionStream(settings, sinks=sinks)
        try:
            self._device.enter_context(stream.streaming())
        except KeyboardInterrupt:  # nothing was recorded yet
            stopped = Stopped(stream.stopped_by or "SIGINT", 0)
            stream.emit(stopped)
            return stopped
        self.stream = stream
        return None

    def _stream(self) -> SessionStream:
        """The session's recorder, opened by ``_lead`` before anything is asked."""
        assert self.stream is not None, "the stream opens before the session leads any step"
        return self.stream

    def _react(self, event: Event) -> None:
        """What the watch saw goes to the session file as it is heard."""
        if isinstance(event, ModelMoved):
            self.log.append("watch", **{k: v for k, v in event.record().items() if k != "event"})

    def _open_log(self) -> SessionState:
        records = self.log.read()
        plan = dataclasses.asdict(self.settings.plan)
        if records and not self.resume:
            raise InputError(
                f"{self.folder} already holds a session; give --resume to continue it, or another --out"
            )
        if self.resume:
            check_resumable(self.log, records)
        if not records:
            self.log.append(
                "plan",
                plan=plan,
                hull=self.settings.hull,
                conditions=[dataclasses.asdict(c) for c in self.conditions],
            )
        else:
            logged = next((r for r in records if r.get("type") == "plan"), None)
            if logged is None or logged.get("plan") != plan or logged.get("hull") != self.settings.hull:
                raise InputError(
                    f"{self.folder} holds a session of another plan or hull; "
                    "resume it with the same PLAN and --hull"
                )
        for line in self.log.skipped + SessionState.from_log(records, self.conditions, 1).problems:
            self.on_line(line)  # each record left out, once, as the session opens
        self.log.append("start", resumed=bool(records), pid=os.getpid(), port=self.record.port)
        adopt_orphans(self.log, self._reload(), self.on_line)
        mark_missing(self.log, self._reload(), self.on_line)
        return self._reload()

    def _open_panel(self, state: SessionState) -> None:
        self.view = open_panel(self.record, self.settings.plan, self._viewer_note)
        for condition in self.conditions:
            self._show_condition(state, condition)

    def _panel(self) -> CampaignView:
        """The campaign panel, opened by ``run`` before the first condition is shown."""
        assert self.view is not None, "the panel opens before the session leads any decay"
        return self.view

    def _viewer_note(self, line: str) -> None:
        self.printer.on_event(ViewerNote(line))

    def _run_name(self, _event: Event) -> str | None:
        """The recorder's run is the session's decay; a release while none was asked for is between decays."""
        return "between decays" if self._decay is None else f"decay {self._decay}"

    def _show_condition(self, state: SessionState, condition: PlannedCondition) -> None:
        show_condition(self._panel(), state, condition)

    def _lead(self, state: SessionState) -> SessionState:
        if state.unjudged() is None and state.next_condition() is None:
            return self._finish(state)
        stopped = self._open_stream()
        pending = state.unjudged()
        if stopped is None and pending is not None:  # recorded before the stop, never judged
            step = self._judge(state, pending)
            stopped = step if isinstance(step, Stopped) else None
        while stopped is None:
            stopped = self._settle_unexpected()
            state = self._reload()
            if stopped is not None or (condition := state.next_condition()) is None:
                break
            self._progress(state, condition)
            if state.draft_ready != condition.draft:
                step = self._set_draft(state, condition)
            else:
                step = self._record_one(state, condition)
            stopped = step if isinstance(step, Stopped) else None
        stopped = stopped or self._stream().stream_until(lambda: True)  # a signal since the last step
        if stopped is not None:  # the recording was stopped: the session ends, resumable
            self.stopped = stopped
            return self._reload()
        self._device.close()  # the report needs no device
        return self._finish(state)

    def _finish(self, state: SessionState) -> SessionState:
        self._progress(state, None)
        if not state.report:
            self._write_report(state)
            state = SessionState.from_log(self.log.read(), self.conditions, state.repeats)
        return state

    def _settle_unexpected(self) -> Stopped | None:
        """A decay released while none was asked for (the model moved during a question): recorded to its
        settle, then kept and logged as rejected, as a recording the log never heard of is."""
        stream = self._stream()
        recorder = stream.recorder
        if recorder.decay_under_way:
            stopped = stream.stream_until(lambda: not recorder.decay_under_way)
            if stopped is not None:
                return stopped
        adopt_orphans(self.log, self._reload(), self.on_line, RELEASED_BETWEEN)
        return None

    def _reload(self) -> SessionState:
        return SessionState.from_log(self.log.read(), self.conditions, self.settings.plan.repeats)

    def _kept(self, state: SessionState) -> tuple[int, int]:
        """Decays kept so far, of those the plan keeps (skipped conditions left out)."""
        total = sum(state.repeats for c in self.conditions if c not in state.skipped)
        done = sum(
            min(len(state.accepted(c)), state.repeats) for c in self.conditions if c not in state.skipped
        )
        return done, total

    def _progress(self, state: SessionState, condition: PlannedCondition | None) -> None:
        done, total = self._kept(state)
        per_decay = float(np.mean(self._decay_seconds)) if self._decay_seconds else None
        left = None if per_decay is None else per_decay * state.runs_left()
        repeat = len(state.accepted(condition)) + 1 if condition else 0
        self.on_progress(
            SessionProgress(
                condition, repeat, done, total, state.decays, time.monotonic() - self._started, left
            )
        )

    def _ask(self, question: Question, decay: int | None) -> str | Stopped:
        """Ask until the answer is a choice, the stream fed meanwhile; notes are logged on the way."""
        while True:
            answer = self._stream().stream_during(lambda: self.operator.ask(question))
            if isinstance(answer, Stopped):
                return answer
            answer = answer.strip()
            if answer.startswith("n ") or answer == "n":
                text = answer[2:].strip()
                if text:
                    self.log.append("note", decay=decay, text=text)
                    self.on_line(f"note kept: {text}")
                continue
            key = answer.lower() or question.default
            if key in question.choices:
                return key
            self.on_line(f"'{answer}' not understood; keys: {keys_line(question)}")

    def _set_draft(self, state: SessionState, condition: PlannedCondition) -> SessionState | Stopped:
        """The operator sets the draft and says when; the still water is then measured before the first
        decay: off level (or still moving), the question comes again."""
        angles = [c.angle_deg for c in self.conditions if c.draft == condition.draft]
        self.watch.disarm()  # the model is handled on purpose while the draft is set
        key = self._ask(draft_question(condition.draft, angles), None)
        if isinstance(key, Stopped):
            return key
        if key == "s":
            for c in self.conditions:
                if c.draft == condition.draft and state.status(c) != "accepted":
                    self.log.append("skip", draft=c.draft, angle_deg=c.angle_deg)
                    self._panel().set_status(c.draft, c.angle_deg, "skipped")
            return self._reload()
        measured = self._measure_level(condition)
        if isinstance(measured, Stopped):
            return measured
        mean_deg, sd_deg = measured
        level = is_level(mean_deg, sd_deg, self.acceptance)
        self.log.append("level", draft=condition.draft, angle_deg=mean_deg, sd_deg=sd_deg, ok=level)
        still = f"still water at {mean_deg:+.2f} deg (sd {sd_deg:.2f} over {LEVEL_S:g} s)"
        if level:
            self.on_line(f"{still}: level")
            self.log.append("draft", draft=condition.draft, action="ready")
            self.watch.arm(mean_deg)  # from now on the model is watched between decays
        else:
            self.on_line(
                f"{still}: not level or not at rest (tolerance {self.acceptance.level_tolerance_deg:g} deg, "
                f"sd {STILL_SD_DEG:g}); re-trim, let it settle and confirm again"
            )
        return self._reload()

    def _measure_level(self, condition: PlannedCondition) -> tuple[float, float] | Stopped:
        """Mean and standard deviation (deg) of the decay axis over ``LEVEL_S`` of device time, or how
        the recording was stopped before that much arrived."""
        self.level.arm()
        stopped = self._stream().stream_until(lambda: self.level.full)
        return stopped if stopped is not None else self.level.mean_sd_deg()

    def _record_one(self, state: SessionState, condition: PlannedCondition) -> SessionState | Stopped:
        decay = state.next_decay
        repeat = len(state.accepted(condition)) + 1
        self.on_line(
            f"decay {decay}: {condition.label}, repeat {repeat}/{state.repeats}: "
            f"tilt to {condition.angle_deg:g} deg and release"
        )
        done, total = self._kept(state)
        label, target = condition.label, condition.angle_deg
        step = SessionStep(decay, done + 1, total, label, target, repeat, state.repeats)
        self._stream().emit(step)  # the operator's panel on a tablet (--viewer web)
        self._panel().set_status(
            condition.draft, condition.angle_deg, "under way", f"{repeat - 1}/{state.repeats}"
        )
        started = time.monotonic()
        stream = self._stream()
        stream.retarget(self._record_settings(condition, decay), run=decay)
        heard_before = len(self.heard.events)

        def settled() -> list[DecayOutcome]:
            events = self.heard.events[heard_before:]
            return [e.outcome for e in events if isinstance(e, Settled) and e.outcome.path is not None]

        self._decay = decay
        try:
            stopped = stream.stream_until(lambda: bool(settled()))
        finally:
            self._decay = None
        if not settled():
            assert stopped is not None
            return stopped  # stopped before a release: nothing recorded, nothing to log
        outcome = settled()[0]
        measured = measure_decay(outcome, condition.angle_deg)
        earlier = [Measured.from_log(r.measured) for r in state.accepted(condition)]
        reasons = check_decay(measured, condition, self.acceptance, earlier)
        reasons += watch_reasons(self.watch.standing_at(decay))  # a bump not settled from, a drifted level
        self.log.append(
            "run",
            decay=decay,
            draft=condition.draft,
            angle_deg=condition.angle_deg,
            file=outcome.path.name if outcome.path else "",
            reasons=reasons,
            measured=dataclasses.asdict(measured),
        )
        if stopped is not None:
            if not outcome.ended.whole:  # stopped mid-decay: logged, the session ends
                self.log.append("verdict", decay=decay, verdict="rejected", action="stopped")
            return stopped  # a whole decay is judged first on resume
        self._decay_seconds.append(time.monotonic() - started)
        state = self._reload()
        return self._judge(state, state.runs[-1])

    def _judge(self, state: SessionState, entry: RunEntry) -> SessionState | Stopped:
        condition = entry.condition
        for reason in entry.reasons:
            self.on_line(f"decay {entry.decay} flagged: {reason}")
        if not entry.reasons:
            m = entry.measured
            self.on_line(
                f"decay {entry.decay} passes: {m['angle_deg']:.1f} deg, {m['half_cycles']} half-cycles, "
                f"R² {m['r2_angle']:.4f}, T0 {m['natural_period_s']:.3f} s, B_eq {m['b_eq_per_s']:.4g} 1/s"
            )
        stream = self._stream()
        stream.emit(SessionVerdict(entry.decay, None, tuple(entry.reasons), "answer at the PC"))
        rejected = sum(1 for r in state.runs if r.condition == condition and r.verdict == "rejected")
        question = verdict_question(entry.decay, condition, bool(entry.reasons), rejected)
        key = self._ask(question, entry.decay)
        if isinstance(key, Stopped):  # unanswered: asked again on resume
            return key
        verdict = "accepted" if key == "a" else "rejected"
        self.log.append(
            "verdict", decay=entry.decay, verdict=verdict, action=question.choices[key], reasons=entry.reasons
        )
        if key == "s":
            self.log.append("skip", draft=condition.draft, angle_deg=condition.angle_deg)
        state = self._reload()
        self.on_verdict(next(r for r in state.runs if r.decay == entry.decay))
        self.on_line(f"decay {entry.decay}: {verdict} ({question.choices[key]})")
        following = state.next_condition()
        after = following.label if following is not None else "the session is done"
        stream.emit(SessionVerdict(entry.decay, Verdict(verdict), tuple(entry.reasons), after))
        self._show_condition(state, condition)
        return state

    # ---- the report ----------------------------------------

    def _write_report(self, state: SessionState) -> None:
        accepted = [path_in(self.folder, r.file) for r in state.runs if r.verdict == "accepted"]
        if not accepted:
            self.on_line("no decay accepted: no report")
            return
        written = write_session_report(
            accepted, self.folder / REPORT_DIR, self.record.model, self.settings.hull
        )
        self.log.append(
            "report",
            files=[str(p.relative_to(self.folder)) for p in written],
            decays=[p.name for p in accepted],
        )
        self.on_line(f"campaign report of {len(accepted)} accepted decays: {self.folder / REPORT_DIR}")
