"""A decay is never lost: any error while a decay is recorded closes its file; readers say when a file is cut.

One real recording (the simulated MTi-G on a pty, through the driver and the daemon) is made per
module. Its raw bytes are fed again through a ``DecayPipeline`` that writes a new file, with a
real failure injected (a view or a callback that raises) at the release, in the middle of the
decay and at its end; every file must then be a complete MCAP (footer, summary) that holds the
decay up to the failure. A copy cut in half stands for a recording whose writer was killed:
every command that reads recordings must say so in one line, and --json carries the flag.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from support.record_settings import sim_record_settings
from tankdaq.acquire.daemon import RecordDaemon
from tankdaq.acquire.decay import LiveDecay, LiveFit
from tankdaq.acquire.events import DeviceLost, Event, Fitted, Released
from tankdaq.acquire.listeners import EventLog
from tankdaq.acquire.pipeline import DecayPipeline, DetectionSettings
from tankdaq.acquire.sinks import RecordingSink, Sink, ViewSink
from tankdaq.cli import app
from tankdaq.device.decoding import SampleDecoder
from tankdaq.device.driver import SILENCE_TIMEOUT_S, StreamBlock
from tankdaq.live.identifier import OnlineIdentifier, OnlineResult
from tankdaq.records import DecayEnd
from tankdaq.store.reader import read_recording
from tankdaq.viz.live import LiveView

runner = CliRunner()


class Injected(RuntimeError):
    """The failure a test injects (a dying viewer, a broken callback)."""


#: One decay at 8x, a fixed seed.
_settings = partial(sim_record_settings, runs=1, sim_speed=8.0, sim_seed=5)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One decay recorded end to end from the simulated MTi-G."""
    (outcome,) = RecordDaemon(_settings(tmp_path_factory.mktemp("rec"))).run()
    assert outcome.path is not None
    return outcome.path


@pytest.fixture(scope="module")
def cut_in_half(recorded: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The recording as a killed writer leaves it: the first half of its bytes, no footer."""
    path = tmp_path_factory.mktemp("cut") / recorded.name
    data = recorded.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def _is_complete_mcap(path: Path) -> bool:
    with path.open("rb") as f:
        return make_reader(f).get_summary() is not None  # a seeking reader needs the footer


# ---- closing on error ---------------------------------------------------------------------------------


class FailingView(LiveView):
    """A view (mode none) whose ``method`` raises, as a dying viewer would: on its ``after``-th call,
    or at the first call whose arguments satisfy ``when``."""

    def __init__(self, method: str, after: int = 1, when: Callable[..., bool] | None = None) -> None:
        super().__init__("none")
        self.calls = 0
        original: Callable[..., object] = getattr(self, method)

        def failing(*args: object, **kwargs: object) -> object:
            self.calls += 1
            if when(*args) if when is not None else self.calls >= after:
                raise Injected(f"{method} failed")
            return original(*args, **kwargs)

        setattr(self, method, failing)


class FailingIdentifier(OnlineIdentifier):
    """An online identifier whose second refit raises, as a bug in a fit would (on the worker thread)."""

    def update(self, t: np.ndarray, angle: np.ndarray, rate: np.ndarray | None = None) -> OnlineResult | None:
        result = super().update(t, angle, rate)
        if result is not None and len(self.results_) >= 2:
            raise Injected("the second refit failed")
        return result


def _feed_recording(
    source: Path,
    out: Path,
    view: LiveView,
    identifier: type[OnlineIdentifier] = OnlineIdentifier,
    extra: Sequence[Sink] = (),
) -> DecayPipeline:
    """The source's raw bytes, re-decoded, through a session that writes into ``out``."""
    recording = read_recording(source)
    sinks = [RecordingSink(out, {"hull": "swath"}), ViewSink(view), *extra]  # the daemon's pipeline
    fit = LiveFit(identifier, wait_for_fits=True)  # fed from a file: each refit in its block
    session = DecayPipeline(DetectionSettings(angle_deg=8.0), sinks, fit=fit)
    decoder = SampleDecoder()
    for host_ns, raw in recording.raw_chunks:
        samples, _ = decoder.feed(raw, host_ns / 1e9)
        session.feed(StreamBlock(samples, raw, host_ns / 1e9))
    session.abort(DecayEnd.STREAM_ENDED, "end of recording")
    return session


@pytest.mark.parametrize(
    ("method", "after", "where"),
    [
        ("new_run", 1, "at the release, as the view opens (before any sample is written)"),
        ("log_samples", None, "4 s into the decay"),
        ("log_fit", 2, "at the second live fit"),
    ],
)
@pytest.mark.slow
def test_a_failure_while_recording_closes_the_file_with_what_arrived(
    recorded: Path, tmp_path: Path, method: str, after: int | None, where: str
) -> None:
    release_t = float(read_recording(recorded).metadata["release_t_s"])
    if after is None:
        view = FailingView(method, when=lambda samples: float(samples["t"][-1]) > release_t + 4.0)
    else:
        view = FailingView(method, after)
    with pytest.raises(Injected):
        _feed_recording(recorded, tmp_path, view)
    (path,) = tmp_path.glob("*.mcap")
    assert _is_complete_mcap(path), where
    recording = read_recording(path)
    kinds = [event["kind"] for event in recording.events]
    assert kinds[-1] == "settled"
    assert any("recording closed after an error" in event["message"] for event in recording.events)
    assert recording.ended is DecayEnd.ERROR
    if method != "new_run":
        assert kinds.count("release") == 1 and recording.samples.size > 0 and recording.raw_chunks
        assert recording.samples.size < len(read_recording(recorded).samples)  # cut where it failed


@pytest.mark.slow
def test_an_identifier_that_fails_mid_decay_closes_the_file_with_what_arrived(
    recorded: Path, tmp_path: Path
) -> None:
    with pytest.raises(Injected):
        _feed_recording(recorded, tmp_path, LiveView("none"), identifier=FailingIdentifier)
    (path,) = tmp_path.glob("*.mcap")
    assert _is_complete_mcap(path)
    recording = read_recording(path)
    assert recording.ended is DecayEnd.ERROR and recording.events[-1]["kind"] == "settled"
    assert len(recording.fits) >= 1  # the first refit was written before the second failed
    assert 0 < recording.samples.size < len(read_recording(recorded).samples)


def _settled(kind: str, *_: object) -> bool:
    return kind == "settled"


# each call is at the decay's end: the view's run ends once, after the file; the settled event (warnings,
# such as an implausible refit's, may come before it)
@pytest.mark.parametrize(("method", "when"), [("end_run", None), ("log_event", _settled)])
@pytest.mark.slow
def test_a_view_that_fails_at_the_end_still_leaves_a_complete_file_with_the_final_fit(
    recorded: Path, tmp_path: Path, method: str, when: Callable[..., bool] | None
) -> None:
    with pytest.raises(Injected):
        _feed_recording(recorded, tmp_path, FailingView(method, when=when))
    (path,) = tmp_path.glob("*.mcap")
    assert _is_complete_mcap(path)
    recording = read_recording(path)
    assert recording.ended is not DecayEnd.ERROR and "fit_b1" in recording.metadata  # the final fit
    assert recording.samples["t"][-1] == read_recording(recorded).samples["t"][-1]  # every sample to the end


class Listener(Sink):
    """One more sink, as a session runner would be: it notes what it hears, and raises ``Injected``
    at the first call named ``fail_at``."""

    def __init__(self, fail_at: str = "") -> None:
        self.heard: list[str] = []
        self.fail_at = fail_at
        self.path_at_release: Path | None = None

    def _hear(self, name: str) -> None:
        self.heard.append(name)
        if name == self.fail_at:
            raise Injected(f"{name} failed")

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> None:
        self._hear("block" if decay is None else "decay block")

    def on_release(self, decay: LiveDecay, pretrigger: Sequence[StreamBlock]) -> None:
        self.path_at_release = decay.path
        self._hear("release")

    def on_event(self, event: Event) -> None:
        if isinstance(event, Fitted):
            self._hear("fit")

    def on_settle(self, decay: LiveDecay) -> None:
        self._hear(f"settle {decay.ended}")

    def close(self) -> None:
        self._hear("close")


@pytest.mark.slow
def test_one_more_sink_hears_the_decay_in_order_after_the_file_is_open(
    recorded: Path, tmp_path: Path
) -> None:
    listener = Listener()
    session = _feed_recording(recorded, tmp_path, LiveView("none"), extra=[listener])
    session.close()
    (outcome,) = session.outcomes
    heard = listener.heard
    release, settle = heard.index("release"), next(i for i, h in enumerate(heard) if h.startswith("settle"))
    assert set(heard[:release]) == {"block"} and heard[-1] == "close" and heard.count("close") == 1
    assert heard[settle] == f"settle {outcome.ended}" and heard.count(heard[settle]) == 1
    assert "fit" in heard[release:settle] and heard[settle - 1] == "fit"  # the final fit, then the settle
    assert listener.path_at_release == outcome.path  # the file (before it in the pipeline) was open
    assert read_recording(outcome.path).ended is outcome.ended


@pytest.mark.parametrize("fail_at", ["release", "fit", "decay block"])
@pytest.mark.slow
def test_a_sink_that_fails_never_takes_the_file_down(recorded: Path, tmp_path: Path, fail_at: str) -> None:
    with pytest.raises(Injected):
        _feed_recording(recorded, tmp_path, LiveView("none"), extra=[Listener(fail_at)])
    (path,) = tmp_path.glob("*.mcap")
    assert _is_complete_mcap(path)
    recording = read_recording(path)
    assert recording.ended is DecayEnd.ERROR
    assert [e["kind"] for e in recording.events][:1] == ["release"]  # the file took what it was given
    assert recording.samples.size > 0 and recording.raw_chunks


@pytest.mark.slow
def test_a_listener_that_raises_in_the_daemon_loop_closes_the_decay(tmp_path: Path) -> None:
    def react(event: Event) -> None:
        if isinstance(event, Released):
            raise Injected("the status display failed")

    daemon = RecordDaemon(_settings(tmp_path), sinks=[EventLog(react)])
    with pytest.raises(Injected):
        daemon.run()
    (path,) = tmp_path.glob("*.mcap")
    assert _is_complete_mcap(path)
    assert read_recording(path).ended is DecayEnd.ERROR


@pytest.mark.slow
def test_a_recorder_kept_busy_longer_than_the_silence_window_loses_no_decay(tmp_path: Path) -> None:
    """The recorder's interpreter taken by one of its own threads for longer than the driver's silence
    window, mid-decay (what a host starved by browsers drawing in software did to it): the simulated MTi-G
    runs in a process of its own, as a sensor is hardware, so it streams on, the reader process reads on,
    and the decay ends whole, every sample in the file. (Its thread in the recorder's process wrote
    nothing that long: "device gone", the decay lost.)"""
    busy: list[float] = []

    def take_the_interpreter(event: Event) -> None:
        """At the first live fit: no other thread of this process runs (the switch interval is longer
        than the spell, so none asks for the interpreter) until the window has passed half again."""
        if isinstance(event, Fitted) and not busy:
            switch = sys.getswitchinterval()
            sys.setswitchinterval(4 * SILENCE_TIMEOUT_S)
            try:
                start = time.monotonic()
                while time.monotonic() - start < 1.5 * SILENCE_TIMEOUT_S:
                    pass
                busy.append(time.monotonic() - start)
            finally:
                sys.setswitchinterval(switch)

    heard = EventLog(take_the_interpreter)
    (outcome,) = RecordDaemon(_settings(tmp_path, reconnect_timeout_s=10.0), sinks=[heard]).run()
    assert busy and busy[0] > SILENCE_TIMEOUT_S
    assert heard.of(DeviceLost) == []
    assert outcome.path is not None
    recording = read_recording(outcome.path)
    assert recording.ended is DecayEnd.SETTLED
    counters = recording.samples["counter"].astype(np.int64)
    assert np.all(np.diff(counters) % 65536 == 1)  # not a sample missing across the busy spell


def test_a_live_model_with_an_input_the_recorder_lacks_is_refused_before_the_device_opens(
    tmp_path: Path,
) -> None:
    from tankdaq.errors import InputError

    out = tmp_path / "out"
    with pytest.raises(InputError, match=r"ku needs a measured input u\(t\)"):
        RecordDaemon(_settings(out, model="b1,c1,ku"))
    assert not out.exists() or not any(out.iterdir())


# ---- readers know truncation --------------------------------------------------------------------------


def _notices(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "cut short" in line]


def _assert_one_notice(stderr: str, path: Path) -> None:
    notices = _notices(stderr)
    assert len(notices) == 1, stderr
    assert str(path) in notices[0] and f"tankdaq recover {path}" in notices[0]
    assert "Traceback" not in stderr


@pytest.mark.slow
def test_the_reader_knows_a_file_is_cut_short(recorded: Path, cut_in_half: Path) -> None:
    whole, cut = read_recording(recorded), read_recording(cut_in_half)
    assert not whole.truncated and cut.truncated
    assert 0 < cut.samples.size < whole.samples.size


@pytest.mark.parametrize("command", ["identify", "diagnose"])
@pytest.mark.slow
def test_json_readers_flag_truncation(recorded: Path, cut_in_half: Path, command: str) -> None:
    extra = ["--max-steps", "0"] if command == "diagnose" else []
    result = runner.invoke(app, [command, str(cut_in_half), "--json", *extra])
    assert result.exit_code == 0, result.output
    _assert_one_notice(result.stderr, cut_in_half)
    document = json.loads(result.stdout)
    assert document["truncated"] is True and document["truncated_files"] == [str(cut_in_half)]
    whole = runner.invoke(app, [command, str(recorded), "--json", *extra])
    assert whole.exit_code == 0, whole.output
    assert json.loads(whole.stdout)["truncated"] is False and not _notices(whole.stderr)


@pytest.mark.slow
def test_replay_says_the_file_is_cut_short(cut_in_half: Path) -> None:
    result = runner.invoke(app, ["replay", str(cut_in_half), "--viewer", "none", "--speed", "max"])
    assert result.exit_code == 0, result.output
    _assert_one_notice(result.stderr, cut_in_half)


@pytest.mark.slow
def test_campaign_says_which_file_is_cut_short(recorded: Path, cut_in_half: Path, tmp_path: Path) -> None:
    folder = tmp_path / "campaign"
    folder.mkdir()
    shutil.copy(recorded, folder / "whole.mcap")
    shutil.copy(cut_in_half, folder / "cut.mcap")
    result = runner.invoke(app, ["campaign", str(folder)])
    assert result.exit_code == 0, result.output
    _assert_one_notice(result.stderr, folder / "cut.mcap")
    assert np.isfinite(float(read_recording(folder / "whole.mcap").metadata["fit_b1"]))


@pytest.mark.slow
def test_export_says_the_file_is_cut_short(cut_in_half: Path, tmp_path: Path) -> None:
    result = runner.invoke(app, ["export", str(cut_in_half), "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    _assert_one_notice(result.stderr, cut_in_half)
    assert (tmp_path / f"{cut_in_half.stem}.csv").is_file()
