"""Status flags with consequences: a decay the gyro clips is flagged in ``record``'s line, the file's
metadata, ``identify`` (text and --json) and a session's checks, and its clipped samples are left out of
the fits; clipping only during the hand's push is noted and harmless. Real pty simulator, real MCAP."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from support.xsens_captures import capture
from tankdaq.acquire.daemon import RecordDaemon, RecordSettings
from tankdaq.acquire.events import DeviceReady, Event, Note, Settled
from tankdaq.acquire.listeners import EventLog
from tankdaq.acquire.sinks import Sink
from tankdaq.cli import app
from tankdaq.config.hulls import hull_scenario
from tankdaq.config.plans import load_campaign_plan
from tankdaq.device.decoding import SampleDecoder
from tankdaq.device.driver import MTiDriver
from tankdaq.device.simulator import Faults, SimulatedMTi
from tankdaq.device.simulator.pty_link import PtyLink
from tankdaq.errors import DeviceGone, InputError
from tankdaq.ident.equation_error import EquationErrorFit
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.scenario import SCRIPTED_FAULTS, DecayScenario, scripted_run
from tankdaq.records import DecayEnd, DecayRun
from tankdaq.samples import (
    STATUS_CLIP_ACC,
    STATUS_CLIP_GYR,
    STATUS_ORIENTATION_VALID,
    StatusTally,
    empty_samples,
    sample_flags,
)
from tankdaq.session.checks import Measured, check_decay
from tankdaq.session.journal import SessionLog
from tankdaq.session.plan import Acceptance, PlannedCondition
from tankdaq.session.runner import GuidedSession, SessionSettings
from tankdaq.store.reader import read_decay_runs, read_recording
from tankdaq.xsens.synthetic import decay_capture

SPEED = 6.0
#: A device clock so fast that the line's byte budget never limits a write (only the latency timer does).
FAST = 1e6


class _PlayWhenReady(Sink):
    """Plays ``scenario`` on the device once the recorder says it is configured and read: the hand's tilt
    then comes while the recorder listens, however long the device took to open on a busy machine (a
    scenario from power-up had its push over before then)."""

    def __init__(self, device: SimulatedMTi, scenario: DecayScenario) -> None:
        self.device = device
        self.scenario = scenario

    def on_event(self, event: Event) -> None:
        if isinstance(event, DeviceReady):
            self.device.play(self.scenario)


def _record(
    tmp_path: Path, fault: str, faults: Faults | None = None
) -> tuple[EventLog, Path, dict[str, float]]:
    """One short decay of the default hull with a scripted fault, recorded through the pty once the
    device streams still water to the recorder; its events."""
    scenario = hull_scenario(runs=1, seed=3, release_after_s=6.0, decay_s=15.0, **scripted_run(fault, 8.0))
    heard = EventLog()
    with SimulatedMTi(hull_scenario(runs=0, seed=3), speed=SPEED, faults=faults) as sim:
        settings = RecordSettings(port=sim.link, draft=1.0, angle_deg=8.0, angle_tolerance_deg=3.0,
                                  out_dir=tmp_path, runs=1, viewer="none")  # fmt: skip
        (outcome,) = RecordDaemon(settings, sinks=[heard, _PlayWhenReady(sim, scenario)]).run()
    assert outcome.path is not None
    return heard, outcome.path, dict(scenario.coefficients)  # the truth's: no fault here changes them


def _identify(path: Path, *extra: str) -> str:
    result = CliRunner().invoke(app, ["identify", str(path), "--model", "b1,b2,c1,c3", *extra])
    assert result.exit_code == 0, result.output
    return result.stdout if "--json" in extra else result.output  # --json: the object alone on stdout


def test_the_status_word_gives_one_set_of_flags() -> None:
    ok = STATUS_ORIENTATION_VALID | 0x1
    words = np.array([0, ok, ok | (STATUS_CLIP_GYR & 0x800), ok & ~STATUS_ORIENTATION_VALID, ok | 0x100])
    flags = sample_flags(words)
    assert flags.gyro_clipped.tolist() == [False, False, True, False, False]
    assert flags.acc_clipped.tolist() == [False, False, False, False, True]
    # start-up (before the first valid orientation) is not a flag; a cleared bit later is
    assert flags.orientation_invalid.tolist() == [False, False, False, True, False]
    assert not sample_flags(np.zeros(5, np.uint32)).unusable.any()  # a device that never reports it
    samples = empty_samples(5)
    samples["t"], samples["status"], samples["roll"], samples["pitch"] = (
        [0.0, 1.0, 1.5, 3.0, 4.0],
        words,
        0.1,
        0,
    )
    tally = StatusTally(release_t=2.0)
    tally.add(samples)
    assert (tally.clipped_before, tally.clipped_after, tally.invalid_after) == (1, 1, 1)
    assert (tally.first_after_s, tally.last_after_s) == (1.0, 2.0)
    assert STATUS_CLIP_ACC & STATUS_CLIP_GYR == 0
    # a message without orientation (GNSS) that sets OrientationValid does not make the rest "invalid"
    gnss_first = sample_flags(np.array([ok, 0x5, 0x5]), oriented=np.array([False, True, True]))
    assert not gnss_first.orientation_invalid.any()


def test_a_real_mti_g_710_capture_flags_nothing() -> None:
    """einride's MTi-G-710 capture: its GNSS message sets OrientationValid, its inertial ones never do."""
    path = capture("einride-1")
    decoder = SampleDecoder()
    samples = np.concatenate([decoder.feed(path.read_bytes(), 0.0)[0], decoder.finish(0.0)[0]])
    assert {int(w) & STATUS_ORIENTATION_VALID for w in samples["status"]} == {0, STATUS_ORIENTATION_VALID}
    tally = StatusTally(release_t=float(samples["t"][0]))
    assert not tally.add(samples).any() and not tally.flagged_after
    assert not sample_flags(samples["status"]).clipped.any()


@pytest.mark.slow
def test_clipping_in_the_decay_is_flagged_everywhere_and_left_out_of_the_fit(tmp_path: Path) -> None:
    heard, path, truth = _record(tmp_path, "clipped-decay")
    warnings = [note for note in heard.of(Note) if note.kind == "warning" and note.run == 1]
    assert any("sensor flagged samples" in note.text for note in warnings), heard.events
    (settled,) = heard.of(Settled)
    assert settled.outcome.path == path and settled.outcome.status is not None
    flagged = settled.outcome.status.describe_after()
    assert "gyro clipped in" in flagged and "after the release" in flagged, flagged
    assert flagged in settled.line()  # the line a person reads says it
    recording = read_recording(path)
    meta = recording.metadata
    assert int(meta["clipped_samples_after_release"]) > 0
    assert int(meta["gyro_clipped_samples_after_release"]) > 0
    assert "flagged_span_after_release_s" in meta
    assert any(e["kind"] == "warning" and "sensor flagged" in e["message"] for e in recording.events)
    (run,) = read_decay_runs(path)
    assert run.excluded is not None and run.excluded.sum() == int(meta["clipped_samples_after_release"])
    text = _identify(path)
    assert "clipped in" in text and "left out of fits" in text
    report = json.loads(_identify(path, "--json"))
    kinds = [finding["check"] for finding in report["plausibility"]]
    assert "clipped" in kinds
    assert any("clipped in" in warning for warning in report["warnings"])
    # the live final fit left them out too: it is the offline fit of the masked decay, up to its last
    # sample (where the detector decided the decay ended; the file goes on to the end of that read)
    live = {
        k.removeprefix("fit_"): float(v)
        for k, v in meta.items()
        if k.startswith("fit_") and k != "fit_r2_angle"
    }
    upto = run.t <= float(recording.fits[-1]["t_s"])
    assert upto.sum() == recording.fits[-1]["samples"]
    assert run.rate is not None and run.excluded is not None
    cut = {"t": run.t[upto], "angle": run.angle[upto], "rate": run.rate[upto], "excluded": run.excluded[upto]}
    fitted = dataclasses.replace(run, **cut, channels={})
    offline = OutputErrorFit(tuple(live)).fit([fitted]).coefficients_
    assert all(abs(live[k] - offline[k]) <= 1e-3 * abs(offline[k]) + 1e-3 for k in live), (live, offline)
    # the clipped samples bias a fit that keeps them; left out, the restoring is the truth's
    terms = tuple(k for k in ("b1", "b2", "b3", "c1", "c2", "c3") if truth.get(k))
    masked = OutputErrorFit(terms).fit([run])
    run.excluded = None
    kept = OutputErrorFit(terms).fit([run])
    error_masked = abs(masked.coefficients_["c3"] - truth["c3"])
    error_kept = abs(kept.coefficients_["c3"] - truth["c3"])
    assert error_masked < 0.1 * truth["c3"] and error_masked < error_kept
    assert masked.sigmas_[0]["rate"] < 0.5 * kept.sigmas_[0]["rate"]  # rate residuals at the noise level


@pytest.mark.slow
def test_clipping_only_during_the_push_is_noted_and_harmless(tmp_path: Path) -> None:
    """Recorded through FTDI-style USB bursts (16 ms) too: the timeline stays the device's."""
    heard, path, _ = _record(tmp_path, "hard-push", Faults.parse("latency=16"))
    assert not [note for note in heard.of(Note) if "sensor flagged" in note.text], heard.events
    (settled,) = heard.of(Settled)
    assert settled.outcome.path == path and settled.outcome.status is not None
    assert not settled.outcome.status.describe_after()
    assert "before the release (the tilt): harmless" in settled.outcome.status.describe_before()
    assert settled.outcome.status.describe_before() in settled.line()  # the line a person reads says it
    recording = read_recording(path)
    meta = recording.metadata
    assert meta["link_gaps"] == "0" and meta["link_lost"] == "0"
    assert np.all(np.diff(recording.samples["ticks"]) == 100)  # 100 Hz on the device clock, bursts or not
    assert int(meta["clipped_samples_before_release"]) > 0
    assert int(meta["clipped_samples_after_release"]) == 0
    (run,) = read_decay_runs(path)
    assert run.excluded is None
    report = json.loads(_identify(path, "--json"))
    assert "clipped" not in [finding["check"] for finding in report["plausibility"]]


def _measured(**changes: object) -> Measured:
    values: dict[str, object] = {
        "angle_deg": 10.0,
        "still_water_deg": 0.0,
        "ended": DecayEnd.SETTLED,
        "half_cycles": 8,
        "r2_angle": 0.999,
        "coefficients": {"b1": 0.2, "c1": 14.0},
        "natural_period_s": 1.7,
        "b_eq_per_s": 0.3,
        "max_rate_deg_s": 30.0,
    }
    return Measured(**{**values, **changes})  # type: ignore[arg-type]


def test_a_session_rejects_a_clipped_decay_unless_the_plan_allows_it() -> None:
    condition = PlannedCondition("T", 10.0)
    why = "gyro clipped in 12 samples (0.10-0.40 s after the release): left out of fits"
    clipped = _measured(flagged_samples=12, flagged_why=why)
    (reason,) = check_decay(clipped, condition, Acceptance(), [])
    assert reason.startswith("clipped: gyro clipped in 12 samples") and "max_flagged_samples 0" in reason
    assert check_decay(clipped, condition, Acceptance(max_flagged_samples=20), []) == []
    assert check_decay(_measured(), condition, Acceptance(), []) == []


class _Operator:
    """Ready for the draft, then walks away (Ctrl-C) at the first verdict it is asked for."""

    def __init__(self) -> None:
        self.asked: list[Any] = []

    def ask(self, question: Any) -> str:
        self.asked.append(question)
        if question.kind != "draft":
            raise KeyboardInterrupt
        return ""


@pytest.mark.slow
def test_a_simulated_session_rejects_the_clipped_decay_with_its_reason(tmp_path: Path) -> None:
    plan_file = tmp_path / "plan.toml"
    plan_file.write_text('hulls = ["swath"]\naxis = "roll"\ndrafts = ["T"]\nangles_deg = [10.0]\n')
    out = tmp_path / "out"
    record = {"port": "sim", "out_dir": out, "viewer": "none", "sim_speed": 20.0}
    settings = SessionSettings(load_campaign_plan(str(plan_file)), "swath", record, {1: "clipped-decay"})
    operator = _Operator()
    with pytest.raises(KeyboardInterrupt):
        GuidedSession(settings, operator).run()
    verdict = operator.asked[-1]
    assert verdict.kind == "verdict" and "failed a check" in verdict.text
    assert verdict.default != "a"  # rejected by default: --yes repeats it
    (run,) = [r for r in SessionLog(out).read() if r["type"] == "run"]
    (reason,) = [reason for reason in run["reasons"] if reason.startswith("clipped: ")]
    assert "gyro clipped in" in reason and "after the release" in reason
    assert run["measured"]["flagged_samples"] > 0


def test_the_scripted_faults_clip_where_they_say() -> None:
    assert {"hard-push", "clipped-decay"} <= set(SCRIPTED_FAULTS)
    for fault, before, after in (("hard-push", True, False), ("clipped-decay", None, True)):
        samples, trace = hull_scenario(runs=1, seed=1, decay_s=8.0, **scripted_run(fault, 8.0)).samples()
        release = trace.runs[0].release_index
        assert release is not None
        flags = sample_flags(samples["status"])
        if before is not None:
            assert bool(flags.clipped[:release].any()) is before
        assert bool(flags.gyro_clipped[release:].any()) is after
        limit = math.radians(300.0 if fault == "hard-push" else 16.0)
        assert np.max(np.abs(samples["p"])) <= limit + 1e-9  # the rate saturates at the range
        assert not flags.orientation_invalid[~flags.clipped].any()  # only clipping clears it


def test_usb_latency_bursts_hold_the_bytes_for_the_timer_period() -> None:
    """The FTDI latency timer (``latency=16`` in the faults): bytes go to the host in one burst per
    period; a write right after a burst keeps the bytes (the 255 ms timer leaves no doubt)."""
    faults = Faults.parse("latency=255")
    assert faults.latency_ms == 255.0
    with pytest.raises(InputError, match="latency"):
        Faults.parse("latency=300")
    link = PtyLink("usb-test-if00-port0")
    link.create()
    try:
        link.plug()
        outbox = bytearray(b"\xfa" * 100)
        link.send(outbox, 115200, FAST, 0.255)  # the first burst goes out at once
        assert not outbox and link.holding(0.255) > 0
        outbox += b"\xfa" * 100
        link.send(outbox, 115200, FAST, 0.255)
        assert len(outbox) == 100  # held for the next burst
        link.send(outbox, 115200, FAST, 0.0)  # without a timer the line carries them
        assert not outbox
    finally:
        link.remove()


def test_the_driver_gives_the_held_last_frame_when_the_device_goes(tmp_path: Path) -> None:
    """The stream ends right after a frame held behind a cut candidate: the driver's last block holds
    it (``finish``), then ``DeviceGone``. A real pty, opened by path; its master closed = unplugged."""
    rows = decay_capture(6, seed=2)
    last = rows[-(len(rows) // 6) :]
    stream = rows + b"\xfa\x13\x37" + last  # a broken header, then an intact frame nothing follows
    master, slave = os.openpty()
    path = os.ttyname(slave)
    driver = MTiDriver(path, rate_hz=100)
    driver.open()
    try:
        os.write(master, stream)
        got = []
        for _ in range(200):  # bounded: until every byte written was read
            got.append(driver.read_block().samples)
            if driver.counters.bytes >= len(stream):
                break
        assert driver.counters.bytes == len(stream)
        os.close(slave)
        os.close(master)
        with pytest.raises(DeviceGone):
            for _ in range(200):
                got.append(driver.read_block().samples)
    finally:
        driver.close()
    samples = np.concatenate(got)
    expected = int.from_bytes(last[12:16], "big")  # the last frame's SampleTimeFine
    assert samples.size == 7 and int(samples["ticks"][-1]) % (1 << 32) == expected


def test_the_equation_error_fit_leaves_the_clipped_samples_out_too() -> None:
    """``--method ee`` (and the output-error fit's seed): no regression row whose smoothing window holds a
    clipped sample; kept, the saturated rate's derivative bends the stiffness."""
    samples, trace = hull_scenario(
        runs=1, seed=1, decay_s=15.0, **scripted_run("clipped-decay", 8.0)
    ).samples()
    truth = trace.runs[0].coefficients
    free = samples[trace.runs[0].release_index :]
    excluded = sample_flags(free["status"]).unusable
    assert excluded.any()
    terms = tuple(k for k in ("b1", "b2", "b3", "c1", "c2", "c3") if truth.get(k))
    errors = []
    for mask in (excluded, None):
        run = DecayRun(free["t"], free["roll"], free["p"], excluded=mask)
        errors.append(abs(EquationErrorFit(terms).fit([run]).coefficients_["c1"] / truth["c1"] - 1))
    assert errors[0] < 0.01 and errors[0] < errors[1] / 3
