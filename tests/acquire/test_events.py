"""The recorder's typed events (``acquire.events``) and their listeners (``acquire.listeners``): each event
renders the line a person reads and a JSON object a program reads; the printer explains the words it
uses once, names runs in the orchestrator's words and shows a session's repeated lines once."""

from __future__ import annotations

import dataclasses
import io
import json
import math
from pathlib import Path

import numpy as np

from tankdaq.acquire.events import (
    SETTLE_REASONS,
    DecayOutcome,
    DeviceBack,
    DeviceLost,
    DeviceReady,
    Event,
    Fitted,
    Held,
    KeptNote,
    ModelMoved,
    Note,
    Notice,
    PutBack,
    Released,
    SessionStep,
    SessionVerdict,
    Settled,
    Stopped,
    Stopping,
    ViewerAddress,
    ViewerNote,
    legend,
)
from tankdaq.acquire.listeners import EventLog, EventPrinter, EventStream
from tankdaq.live.identifier import OnlineResult
from tankdaq.records import DecayEnd, Verdict


def _fit() -> OnlineResult:
    t = np.linspace(0.0, 1.0, 5)
    return OnlineResult(
        t_end=12.5, half_cycles=6, n_samples=500, coefficients={"b1": 0.2, "c1": 14.2}, std={}, ci95={},
        r2_angle=0.998, natural_period_s=1.667, offset=0.0, elapsed_s=0.01, predicted_t=t,
        predicted_angle=np.zeros_like(t),
    )  # fmt: skip


def _every_event() -> list[Event]:
    outcome = DecayOutcome(
        run=2, axis="roll", path=Path("rec/run02.mcap"), rrd_path=None, release_t=14.25,
        angle_initial_deg=-8.3, ended=DecayEnd.SETTLED, fit=_fit(), warnings=["off the nominal"], last_t=40.0,
    )  # fmt: skip
    return [
        Notice("device", "simulated MTi-G on /tmp/x (swath T roll)"), ViewerNote("save, as asked"),
        DeviceReady("MTi-G-710 on /tmp/x"), Held(-8.31, "roll"), PutBack(), Released(2, -8.3, "roll", 14.25),
        Note("warning", "fit at 4.2 s: implausible damping", 2), Note("note", "sensor clipped in 3 samples"),
        Fitted(2, _fit()), Settled(outcome), DeviceLost("read failed", 120.0), DeviceBack(2.14),
        Stopping("SIGTERM"), Stopped("SIGTERM", 2), ModelMoved("drift", 1.23, 0.02, 0.2, 0.03, 1.0, 30.5),
        ModelMoved("bump", 0.1, 0.71, 2.7, 0.03, 0.3, 31.5),
        ModelMoved("level", 1.1, 0.02, 0.2, 0.6, 1.0, 32.5),
        ModelMoved("trend", 0.41, 0.02, 0.2, 0.03, 1.0, 33.5, 2.2),
        KeptNote("note", "recording stopped by the operator", 2),
        ViewerAddress("http://192.168.1.20:9090/?url=x", "██"), SessionStep(3, 2, 4, "T 6 deg", 6.0, 1, 2),
        SessionVerdict(3, None, ("R² 0.97",), "answer at the PC"),
    ]  # fmt: skip


def test_every_event_is_a_line_and_a_json_object_of_its_values() -> None:
    events = _every_event()
    assert {type(e) for e in events} == {cls for cls in _subclasses(Event)}, "a new event is tested here"
    for event in events:
        record = json.loads(json.dumps(event.record()))  # plain JSON, no default= needed
        assert record["event"] and event.line()
    released = Released(2, -8.3, "roll", 14.25)
    assert released.record() == {
        "event": "released",
        "run": 2,
        "angle_deg": -8.3,
        "axis": "roll",
        "t_s": 14.25,
        "u95_s": None,  # unknown: never said as zero
    }
    assert released.line() == "run 2: released at 8.30 deg (roll), t = 14.250 s (interval unknown)"
    assert released.line("decay 5") == "decay 5: released at 8.30 deg (roll), t = 14.250 s (interval unknown)"
    bracketed = Released(2, -8.3, "roll", 14.25, 0.0021)
    assert bracketed.line() == "run 2: released at 8.30 deg (roll), t = 14.2500 s ± 2.1 ms (95 %)"
    settled = next(e for e in events if isinstance(e, Settled))
    assert settled.record()["coefficients"] == {"b1": 0.2, "c1": 14.2}
    assert settled.line() == "run 2: settled; b1=0.2  c1=14.2, T0 1.667 s, R2 0.9980 -> rec/run02.mcap"
    assert settled.record()["ended"] == "settled" and settled.record()["whole"] is True
    early = dataclasses.replace(
        settled.outcome, ended=DecayEnd.STOPPED, fit=dataclasses.replace(_fit(), half_cycles=3), last_t=17.25
    )
    assert Settled(
        early
    ).line() == (  # stopped a cycle after the release: partial, and its live fit no result
        "run 2: stopped by the operator 3.0 s after the release: partial, left out of campaigns; "
        "b1=0.2  c1=14.2, T0 1.667 s, R2 0.9980; a live fit over 3 half-cycle(s) only: "
        "fit the file with tankdaq identify -> rec/run02.mcap"
    )
    said = Settled(early).record()
    assert (said["ended"], said["whole"], said["ended_after_s"]) == ("stopped", False, 3.0)
    unplugged = Settled(dataclasses.replace(early, ended=DecayEnd.DEVICE_LOST)).line()
    assert unplugged.startswith("run 2: the device went away 3.0 s after the release: partial,")
    assert Note("note", "x").line() == "note: x" and Note("warning", "x", 3).line() == "warning: run 3: x"
    assert Stopping("SIGHUP").line() == "stopping (SIGHUP): closing files"
    assert Held(math.nan, "roll").record()["angle_deg"] is None  # NaN is no JSON
    address = ViewerAddress("http://192.168.1.20:9090/?url=x", "██")
    assert address.line().endswith("(same network; view only)\n██") and "qr" not in address.record()
    judged = SessionVerdict(3, Verdict.ACCEPTED, (), "T 8 deg")
    assert judged.line() == "decay 3: accepted (every check passed); next: T 8 deg"
    assert judged.record()["verdict"] == "accepted" and SessionVerdict(3, None, (), "").said == "to judge"


def _subclasses(cls: type) -> set[type]:
    return {sub for direct in cls.__subclasses__() for sub in (direct, *_subclasses(direct))}


def test_the_printer_explains_its_words_once_and_names_runs_as_asked() -> None:
    out: list[str] = []
    printer = EventPrinter(out.append, run_name=lambda _e: "decay 7", once=(ViewerNote,))
    for event in [*_every_event(), *_every_event()]:
        printer.on_event(event)
    settle_legend, note_legend = legend(_every_event()[9]), legend(Note("note", ""))
    assert settle_legend is not None and note_legend is not None
    assert out.count(settle_legend) == 1 and out.count(note_legend) == 1
    assert all(f"{end.value} = " in settle_legend for end in SETTLE_REASONS)  # every end a run can have
    assert set(SETTLE_REASONS) == set(DecayEnd) - {DecayEnd.CUT, DecayEnd.RECOVERED}  # a recorder's ends
    first_settled = out.index(_every_event()[9].line("decay 7"))
    assert out[first_settled - 1] == settle_legend  # said just before the first line that needs it
    assert out.count(ViewerNote("save, as asked").line()) == 1  # shown once
    assert out.count(Held(-8.31, "roll").line()) == 2  # the others every time
    assert not [line for line in out if "fit to 12.50 s" in line or "recording stopped by" in line]  # quiet


def test_the_log_waits_for_an_event_and_the_stream_writes_json_lines() -> None:
    log = EventLog()
    sink = io.StringIO()
    stream = EventStream(sink)
    for event in _every_event():
        log.on_event(event)
        stream.on_event(event)
    assert log.wait_for(Stopped, 0.0) == Stopped("SIGTERM", 2) and log.wait_for(PutBack, 0.0) == PutBack()
    assert log.of(Note) == [e for e in _every_event() if isinstance(e, Note)]
    assert EventLog().wait_for(Released, 0.01) is None
    lines = sink.getvalue().splitlines()
    streamed = [e.record()["event"] for e in _every_event() if not isinstance(e, KeptNote)]
    assert [json.loads(line)["event"] for line in lines] == streamed  # a kept note: the decay's only
