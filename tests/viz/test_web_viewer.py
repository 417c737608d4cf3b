"""``--viewer web`` in a real browser: ``tankdaq record`` and ``tankdaq session`` on the simulated MTi-G
serve rerun's web viewer, Debian's Chromium (headless, through playwright) opens the printed address, and
what the viewer holds (its recording read back) and draws (a screenshot at a phone's and a tablet's
size) is checked: the angle trace and the model, the operator's panel with the step and the verdict, a
reload mid-decay from its release. Browsers killed, or five at once, change nothing in the recordings
(against the same seed with no browser). The screenshots are docs/img/live-view-*.png
(docs/live-view.md); support/web_browser.py says how the pages are kept cheap to draw.

One recorder run (``served``) is shared by the browser tests of ``record``; each page is opened small (a
page drawn in software at full size falls behind a decay), follows the recording, and is brought to the
phone's or the tablet's size for its screenshot, then closed.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from support.web_browser import (
    FAST_SPEED,
    PHONE,
    SMALL,
    TABLET,
    WATCHED_SPEED,
    RunningTankdaq,
    SettleMemory,
    Shown,
    children,
    chromium,
    colour_pixels,
    free_ports,
    listening_ports,
    new_page,
    own_chromium,
    record_args,
    wait_shown,
)
from tankdaq.acquire.events import Held, Released, SessionStep, SessionVerdict, ViewerAddress
from tankdaq.acquire.live_panel import LivePanel
from tankdaq.device.driver import StreamBlock
from tankdaq.records import Verdict
from tankdaq.samples import empty_samples
from tankdaq.store.reader import read_recording
from tankdaq.viz.live import MEASURED_COLOR, MODEL_COLOR
from tankdaq.viz.viewer import check_mode
from tankdaq.viz.web_view import decimate
from tankdaq.viz.web_viewer import WebAddress, lan_address

IMAGES = Path(__file__).resolve().parents[2] / "docs" / "img"
#: Every field the device sent: a recording's samples share them with another run of the same seed and
#: script (the host's arrival time is the machine's).
DEVICE_FIELDS = ("t", "ticks", "counter", "roll", "pitch", "yaw", "p", "q", "r", "ax", "ay", "az", "status")
#: The recorder's decays compared with the run without a browser: the first, released as a browser is
#: killed, while five pages take it in at once.
COMPARED = 1
#: Two animation frames: a page resized has drawn itself at its new size.
FRAMES_JS = "() => new Promise(done => requestAnimationFrame(() => requestAnimationFrame(() => done(true))))"


def released(seen: Shown, at: float) -> bool:
    """The page holds the release at device time ``at`` and a second of the decay after it."""
    t, _angle = seen.scalars("/angle/measured")
    return any(abs(r - at) < 1e-3 for r in seen.releases()) and t.size > 0 and t.max() > at + 1.0


def settled(seen: Shown, at: float) -> bool:
    """The page holds the decay released at ``at`` to its settle, with its models."""
    return fitted(seen, at) and np.isfinite(settle_of(seen, at))


def fitted(seen: Shown, at: float, fits: int = 2) -> bool:
    """The page holds the decay released at ``at`` and ``fits`` of its models (curves from its release)."""
    curves = [seen.scalars(entity)[0] for entity in seen.fits()]
    own = [t for t in curves if t.size and t.min() >= at - 1.0]
    return released(seen, at) and len(own) >= fits


def measuring(seen: Shown) -> bool:
    return seen.scalars("/angle/measured")[0].size > 0


def settle_of(seen: Shown, at: float) -> float:
    """The device time the page's events say the decay released at ``at`` settled (inf: not yet)."""
    return min([t for t, text in seen.texts("/events") if text.startswith("settled:") and t > at] or [np.inf])


def around_release(seen: Shown, at: float) -> tuple[np.ndarray, np.ndarray]:
    """The page's angle samples of the decay released at device time ``at``, from its pre-trigger to its
    settle, in seconds from its release."""
    t, angle = seen.scalars("/angle/measured")
    inside = (t > at - 30.0) & (t <= settle_of(seen, at))
    return t[inside] - at, angle[inside]


def contents(folder: Path) -> list[dict[str, Any]]:
    """The first ``COMPARED`` recordings' device samples, release and end, and final fit (what a browser
    must never change)."""
    kept = []
    for path in sorted(folder.glob("*.mcap"))[:COMPARED]:
        recording = read_recording(path)
        meta = recording.metadata
        kept.append(
            {
                "samples": {name: recording.samples[name] for name in DEVICE_FIELDS},
                "release_t_s": meta["release_t_s"],
                "ended": meta["ended"],
                "fit": recording.fits[-1],
            }
        )
    return kept


#: The longest a page may take to settle its drawing after a resize (s): a deadline, not a wait.
DRAWN_S = 30.0


#: How much the model's pixel count may change between two frames of a settled drawing (the live trace
#: beside it scrolls on as the next decay's samples arrive, and the plot's bounds with it).
DRAWN_CHANGE = 0.05


def screenshot(page: Any, size: dict[str, int], name: str) -> bytes:
    """The page brought to ``size`` and drawn there: shot frame after frame until the model covers as
    many pixels as in the frame before, to ``DRAWN_CHANGE`` (a busy machine's browser lays out and fits
    the plots over several frames), that screenshot written to docs/img/``name``."""
    page.set_viewport_size(size)
    deadline = time.monotonic() + DRAWN_S
    drawn = -1
    while True:
        page.evaluate(FRAMES_JS)
        shot = bytes(page.screenshot())
        before, drawn = drawn, colour_pixels(shot, MODEL_COLOR)
        if abs(drawn - before) <= DRAWN_CHANGE * drawn or time.monotonic() > deadline:
            (IMAGES / name).write_bytes(shot)
            return shot


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Decays recorded with the web viewer while browsers come and go: five pages (the phone's, the
    tablet's and three more) and a browser of its own from the start; that browser killed as decay 1 is
    released, the three closed once they show decay 1, the phone's page reloaded as a later decay is
    released; the recorder stopped (Ctrl-C) once that decay settled. Then the same seed recorded with
    ``web,save`` and no browser at all."""
    folder = tmp_path_factory.mktemp("web")
    ports = free_ports(4)
    memory = SettleMemory()
    with contextlib.ExitStack() as stack:
        recorder = stack.enter_context(
            RunningTankdaq(
                record_args(folder / "watched", None, ports[:2], speed=WATCHED_SPEED), folder, on_event=memory
            )
        )
        memory.pid = pid = recorder.process.pid
        url = recorder.url
        browser = stack.enter_context(chromium())
        pages = {name: new_page(browser, SMALL, url) for name in ("phone", "tablet", "3", "4", "5")}
        killed = stack.enter_context(own_chromium(url))
        first = recorder.release_at(1)
        os.killpg(killed.pid, signal.SIGKILL)  # mid-decay
        listens = {"own": listening_ports(pid), "children": [listening_ports(c) for c in children(pid)]}
        niceness = {"own": os.getpriority(os.PRIO_PROCESS, pid)} | {
            "server": max(os.getpriority(os.PRIO_PROCESS, c) for c in children(pid) if listening_ports(c))
        }
        at_once = {
            name: wait_shown(page, lambda seen: released(seen, first), "decay 1")
            for name, page in pages.items()
        }
        for name in ("3", "4", "5"):
            pages.pop(name).close()
        phone, tablet = pages["phone"], pages["tablet"]
        run = 1 + recorder.count("released")
        reloaded_at = recorder.release_at(run)
        settled_before = recorder.count("settled") >= run
        phone.reload()
        phone_seen = wait_shown(phone, lambda seen: settled(seen, reloaded_at), f"decay {run} and its model")
        shots = {"phone": screenshot(phone, PHONE, "live-view-phone.png")}
        phone.close()
        tablet_seen = wait_shown(
            tablet, lambda seen: settled(seen, reloaded_at), f"decay {run} and its model"
        )
        shots["tablet"] = screenshot(tablet, TABLET, "live-view-tablet.png")
        tablet.close()
        recorder.wait_event("settled", run=max(run, COMPARED))
        code = recorder.interrupt()
    # the run without a browser after the browsers are gone: nothing else of the test's takes the cores
    with (
        RunningTankdaq(  # the same script as the watched run (its length draws the noise), stopped alike
            record_args(folder / "alone", None, ports[2:], viewer="web,save"), folder
        ) as alone
    ):
        alone.wait_event("settled", run=COMPARED)
        alone_code = alone.interrupt()
    return {
        "code": code,
        "alone_code": alone_code,
        "alone_lines": list(alone.lines),
        "lines": list(recorder.lines),
        "url": url,
        "ports": ports[:2],
        "listens": listens,
        "niceness": niceness,
        "first": first,
        "reloaded_at": reloaded_at,
        "settled_before_reload": settled_before,
        "at_once": at_once,
        "phone": phone_seen,
        "tablet": tablet_seen,
        "shots": shots,
        "memory": memory.own,
        "watched": contents(folder / "watched"),
        "alone": contents(folder / "alone"),
        "alone_folder": folder / "alone",
    }


@pytest.mark.slow
def test_the_printed_address_is_the_one_asked_and_its_qr_code_follows(served: dict[str, Any]) -> None:
    lines, (grpc, web) = served["lines"], served["ports"]
    assert served["code"] == 130, "\n".join(lines)  # stopped by Ctrl-C, its files closed
    assert served["url"] == WebAddress("127.0.0.1", grpc, web).tablet_url  # the address and ports asked
    assert f"%2F%2F127.0.0.1%3A{grpc}%2Fproxy" in served["url"]  # the data server's, on the same host
    said = lines.index(ViewerAddress(served["url"]).line())  # printed for people, as the event says
    assert lines[said + 1].startswith("█") and len(lines[said + 1]) == len(lines[said + 2])  # the QR code


@pytest.mark.slow
def test_the_phone_and_the_tablet_draw_the_angle_and_the_model(served: dict[str, Any]) -> None:
    for size in ("phone", "tablet"):
        seen: Shown = served[size]
        t, angle = around_release(seen, served["reloaded_at"])
        assert t.min() < 0 < t.max() and np.abs(angle).max() > 5.0  # the decay from before its release
        step = np.median(np.diff(t))
        assert 1 / 50.5 < step < 1 / 45, step  # decimated to the web rate (recorded at 100 Hz)
        assert "→ target 8°" in seen.text("/session")  # the operator's panel: the angle against the target
        shot = served["shots"][size]
        assert colour_pixels(shot, MEASURED_COLOR) > 200, size  # the trace, drawn
        assert colour_pixels(shot, MODEL_COLOR) > 100, size  # the model, drawn over it
        assert (IMAGES / f"live-view-{size}.png").stat().st_size > 10_000


@pytest.mark.slow
def test_a_reload_mid_decay_shows_the_decay_from_its_release(served: dict[str, Any]) -> None:
    assert not served["settled_before_reload"]  # reloaded while the decay was under way
    seen: Shown = served["phone"]  # reloaded as the decay was released
    t, angle = around_release(seen, served["reloaded_at"])
    assert t.min() < 0.0 < 1.0 < t.max()  # from before the release, though reloaded after it
    assert np.all(np.diff(t[t > -1.0]) < 0.05)  # with no hole
    assert np.abs(angle[(t > -1.0) & (t <= 0.1)]).max() > 5.0  # the tilt it was released from
    assert fitted(seen, served["reloaded_at"])  # and the models fitted to it


@pytest.mark.slow
def test_the_web_side_is_view_only_and_yields_the_cores_to_the_recorder(served: dict[str, Any]) -> None:
    listens = served["listens"]
    assert listens["own"] == set()  # the recorder takes nothing from the network
    assert set(served["ports"]) in listens["children"]  # only the viewer's server listens, on its two ports
    niceness = served[
        "niceness"
    ]  # pages reloading keep the server busy: it must not starve the device's reads
    assert niceness["server"] >= niceness["own"] + 10, niceness


@pytest.mark.slow
def test_five_browsers_at_once_each_see_the_decay(served: dict[str, Any]) -> None:
    assert len(served["at_once"]) == 5
    for seen in served["at_once"].values():
        assert released(seen, served["first"])  # connected and served decay 1 as it happened


@pytest.mark.slow
def test_browsers_killed_or_many_leave_the_recordings_as_without_any(served: dict[str, Any]) -> None:
    """Each file is cut at a read of the device (its first and last block), and the wall clock decides
    where the reads fall, browser or not: the samples are compared where both files hold them (from the
    pre-trigger to the settle), every device field equal and none missing; the release the same instant
    (to a microsecond: the device's clock ticks every 100); the final fit, made of the samples up to
    where the detector decided the decay ended, equal to the last bit."""
    assert served["alone_code"] == 130
    watched, alone = served["watched"], served["alone"]  # the watched run went on until stopped
    assert len(watched) == len(alone) == COMPARED
    for ours, theirs in zip(watched, alone, strict=True):
        assert abs(float(ours["release_t_s"]) - float(theirs["release_t_s"])) < 1e-6
        ended = (ours["ended"], theirs["ended"])
        assert ended == ("settled", "settled"), (ended, served["lines"][-30:], served["alone_lines"][-30:])
        t, t_alone = ours["samples"]["t"], theirs["samples"]["t"]
        start, end = max(t[0], t_alone[0]), min(t[-1], t_alone[-1])
        assert end - start > 10.0 and start < float(ours["release_t_s"]) - 1.0  # the decay, both hold it
        for name in DEVICE_FIELDS:
            ours_, theirs_ = ours["samples"][name], theirs["samples"][name]
            np.testing.assert_array_equal(
                ours_[(t >= start) & (t <= end)], theirs_[(t_alone >= start) & (t_alone <= end)], err_msg=name
            )
        assert np.all(np.diff(ours["samples"]["counter"].astype(int)) % 65536 == 1)  # none lost
        fit, fit_alone = ours["fit"], theirs["fit"]
        for key in ("terms", "samples", "t_s", "coefficients", "ci95"):
            assert fit[key] == fit_alone[key], (key, fit[key], fit_alone[key])


@pytest.mark.slow
def test_memory_stays_flat_over_the_decays_with_browsers(served: dict[str, Any]) -> None:
    own = served["memory"]  # bench/bench_web_memory.py: over 100 decays
    assert len(own) >= 2 and max(own) - min(own) < 50.0, own  # the reload waits for a second decay


@pytest.mark.slow
def test_web_and_save_write_every_sample_to_an_rrd_beside_each_recording(served: dict[str, Any]) -> None:
    from rerun.chunk import RrdReader

    for mcap in sorted(served["alone_folder"].glob("*.mcap")):
        chunks = RrdReader(mcap.with_suffix(".rrd")).stream().to_chunks()
        batches = [c.to_record_batch() for c in chunks if c.entity_path == "/angle/measured"]
        times = [float(t.value) / 1e9 for b in batches if "t" in b.schema.names for t in b.column("t")]
        t = np.sort(times)
        assert t.min() < 0 < t.max() < 200  # seconds from the release, as --viewer save writes it
        assert np.median(np.diff(t)) < 0.015  # the device's 100 Hz, not the web's 50 Hz


PLAN = 'hulls = ["swath"]\naxis = "roll"\ndrafts = ["T", "1.1T"]\nangles_deg = [8.0]\nrepeats = 1\n'


@pytest.mark.slow
def test_a_guided_session_shows_its_step_and_verdict_on_the_tablet(tmp_path: Path) -> None:
    (tmp_path / "plan.toml").write_text(PLAN)
    (tmp_path / "answers.txt").write_text("\na\n")  # draft T set; decay 1 accepted; then the terminal
    grpc, web = free_ports(2)
    args = ["session", "plan.toml", "--port", "sim", "--hull", "swath", "--out", "s", "--seed", "0"]
    args += ["--responses", "answers.txt", "--sim-speed", WATCHED_SPEED, "--viewer", "web"]
    args += ["--viewer-bind", "127.0.0.1", "--viewer-port", str(grpc), "--viewer-web-port", str(web)]
    args += ["--events", "jsonl"]
    ours, theirs = os.openpty()  # the next draft's question waits at this terminal: the panel holds still
    try:
        with RunningTankdaq(args, tmp_path, stdin=theirs) as session, chromium() as browser:
            page = new_page(browser, SMALL, session.url)

            def judged(seen: Shown) -> bool:
                return "decay 1 **ACCEPTED**" in seen.text("/session") and bool(seen.fits())

            seen = wait_shown(page, judged, "decay 1 accepted")
            shot = screenshot(page, TABLET, "live-view-session.png")
            page.context.close()
            assert session.interrupt() == 130, session.said()
    finally:
        os.close(ours)
        os.close(theirs)
    panel = seen.text("/session")
    assert "Step 1 of 2 · decay 1" in panel and "**T 8 deg**, repeat 1/1" in panel, panel
    assert "→ target 8°" in panel and "## Next: 1.1T 8 deg" in panel, panel
    assert colour_pixels(shot, MEASURED_COLOR) > 200 and colour_pixels(shot, MODEL_COLOR) > 100


# ---- without a browser ----------------------------------------------------------------------------


def test_the_address_for_a_tablet_is_the_network_one_unless_asked() -> None:
    lan = lan_address()
    if lan is None:
        pytest.skip("this machine has no network interface besides loopback")
    wildcard = WebAddress("0.0.0.0", 9876, 9090)
    assert wildcard.host == lan and not lan.startswith("127.")  # never connected to: checked as printed
    assert wildcard.data_url.startswith("rerun+http://127.0.0.1:")  # the views stream on this machine
    assert WebAddress("127.0.0.1").tablet_url.startswith("http://127.0.0.1:9090/?url=rerun%2Bhttp")


@pytest.mark.slow  # a recorder of its own
def test_without_a_bind_the_address_printed_is_the_network_one(tmp_path: Path) -> None:
    lan = lan_address()
    if lan is None:
        pytest.skip("this machine has no network interface besides loopback")
    args = record_args(tmp_path / "r", 1, free_ports(2), bind=None, speed=FAST_SPEED)
    with RunningTankdaq(args, tmp_path) as recorder:
        url = recorder.url  # printed, never connected to
    assert url.startswith(f"http://{lan}:") and f"%2F%2F{lan}%3A" in url and lan != "127.0.0.1"


@pytest.mark.slow  # a recorder of its own
def test_a_port_in_use_is_one_line_before_the_device_opens(tmp_path: Path) -> None:
    grpc, web = free_ports(2)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", web))
        taken.listen()
        with RunningTankdaq(record_args(tmp_path / "r", 1, [grpc, web]), tmp_path) as recorder:
            code = recorder.finish()
    said = [line for line in recorder.lines if line]
    assert code == 1 and len(said) == 1, said
    assert f"port {web} on 127.0.0.1 is in use" in said[0] and "--viewer-web-port" in said[0]
    assert not (tmp_path / "r").exists() or not list((tmp_path / "r").iterdir())  # no device, no file


def test_web_and_save_combine_and_the_feed_keeps_one_sample_per_slot() -> None:
    assert check_mode("web,save") == check_mode("save,web") == "web+save" and check_mode("web") == "web"
    t = np.arange(0.0, 2.0, 0.01)  # 100 Hz in two blocks
    first, slot = decimate(t[:77], 50.0, -np.inf)
    second, _ = decimate(t[77:], 50.0, slot)
    kept = np.concatenate([t[:77][first], t[77:][second]])
    np.testing.assert_allclose(np.diff(kept), 0.02)
    assert kept.size == 100


class Pages:
    """A view's panel calls kept in order (what the web view would draw)."""

    def __init__(self) -> None:
        self.shown: list[tuple[str, float]] = []

    def log_panel(self, markdown: str, t_s: float) -> None:
        self.shown.append((markdown, t_s))


def block_at(t_s: float, roll_rad: float) -> StreamBlock:
    """One sample's block at device time ``t_s``."""
    samples = empty_samples(1)
    samples["t"], samples["roll"] = t_s, roll_rad
    return StreamBlock(samples, b"", 0.0)


def test_the_operator_panel_says_the_step_the_angle_and_the_verdict() -> None:
    pages = Pages()
    panel = LivePanel(pages, "roll", 8.0)
    panel.on_event(SessionStep(3, 2, 4, "T 6 deg", 6.0, 1, 2))
    assert pages.shown == []  # nothing to show before the first sample: the angle now is unknown
    panel.on_block(block_at(10.0, math.radians(5.9)), None)
    page, t_s = pages.shown[-1]
    assert t_s == 10.0 and "Step 2 of 4 · decay 3" in page and "# +5.9° → target 6°" in page
    panel.on_event(Held(5.9, "roll"))
    assert "Held at 5.9°: release when still" in pages.shown[-1][0]
    panel.on_event(Released(3, 5.9, "roll", 10.0))
    assert "hands off" in pages.shown[-1][0]
    panel.on_event(SessionVerdict(3, None, ("R² 0.97 under 0.99",), "answer at the PC"))
    assert "decay 3 **TO JUDGE** — R² 0.97 under 0.99" in pages.shown[-1][0]
    assert "Answer at the PC" in pages.shown[-1][0]
    panel.on_event(SessionVerdict(3, Verdict.REJECTED, ("R² 0.97 under 0.99",), "T 6 deg"))
    assert "decay 3 **REJECTED**" in pages.shown[-1][0] and "## Next: T 6 deg" in pages.shown[-1][0]
    count = len(pages.shown)
    panel.on_block(block_at(10.1, math.radians(5.8)), None)  # within the refresh: not redrawn
    assert len(pages.shown) == count
