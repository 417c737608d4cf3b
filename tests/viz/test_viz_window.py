"""The real rerun viewer in a window: ``record --port sim --viewer spawn`` under a virtual X server.

Xvfb gives the display, Mesa's lavapipe the (software) Vulkan driver the viewer renders with.
The screenshot is the viewer's own capture of its window (``ViewerClient.save_screenshot``):
an X-level grab of an Xvfb screen stays black, because lavapipe's frames are not presented
to it. Skipped, with the reason, where Xvfb or lavapipe is missing (``make test`` installs both
where it runs as root with apt-get).
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import select
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread
from mcap.reader import make_reader

from tankdaq.viz.live import MEASURED_COLOR, MODEL_COLOR

XVFB = shutil.which("Xvfb")
LAVAPIPE = sorted(Path("/usr/share/vulkan/icd.d").glob("lvp_icd*.json"))

pytestmark = pytest.mark.skipif(
    XVFB is None or not LAVAPIPE,
    reason="needs Xvfb and a software Vulkan driver (Debian packages xvfb and mesa-vulkan-drivers; "
    "make test installs them when it runs as root with apt-get)",
)


@contextlib.contextmanager
def virtual_display() -> Iterator[str]:
    """An Xvfb server on a free display number (it names the number itself); always stopped."""
    assert XVFB is not None
    read_end, write_end = os.pipe()
    server = subprocess.Popen(
        [XVFB, "-displayfd", str(write_end), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
        pass_fds=(write_end,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_end)
    try:
        ready, _, _ = select.select([read_end], [], [], 60)
        number = os.read(read_end, 64).decode().strip() if ready else ""
        assert number.isdigit(), "Xvfb did not start"
        yield f":{number}"
    finally:
        os.close(read_end)
        server.terminate()
        server.wait(timeout=10)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _events(stream) -> queue.Queue[dict | None]:
    """The process's event stream (``--events jsonl`` on stdout), read on a thread (``None`` at its end)."""
    events: queue.Queue[dict | None] = queue.Queue()

    def pump() -> None:
        for line in stream:
            events.put(json.loads(line))
        events.put(None)

    threading.Thread(target=pump, daemon=True).start()
    return events


def _wait_for(
    events: queue.Queue[dict | None],
    seen: list[dict],
    wanted: Callable[[dict], bool],
    deadline_s: float = 180,
) -> dict:
    """The first event ``wanted`` holds true of (those before it go to ``seen``)."""
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        try:
            event = events.get(timeout=1)
        except queue.Empty:
            continue
        if event is None:
            raise AssertionError(f"tankdaq ended before the event waited for: {seen}")
        seen.append(event)
        if wanted(event):
            return event
    raise AssertionError(f"not the event waited for within {deadline_s:g} s: {seen}")


def _viewer_said(words: str) -> Callable[[dict], bool]:
    return lambda event: event["event"] == "viewer_note" and words in event["text"]


def _settled(run: int | None = None) -> Callable[[dict], bool]:
    """A whole decay's end: run ``run``, or the next one (None)."""
    return lambda event: (
        event["event"] == "settled" and run in (None, event["run"]) and event["ended"] == "settled"
    )


def _screenshot_once_drawn(client: object, shot: Path, deadline_s: float = 120) -> np.ndarray:
    """The viewer's window once it shows the measured decay and the fitted model, else its last capture
    at the deadline: the recorder's event says what it sent; the viewer, a process of its own on a loaded
    machine, draws it when it can."""
    deadline = time.monotonic() + deadline_s
    while True:
        client.save_screenshot(str(shot))  # type: ignore[attr-defined]
        image = imread(shot)
        drawn = all(_pixels_near(image, color) > 500 for color in (MEASURED_COLOR, MODEL_COLOR))
        if drawn or time.monotonic() > deadline:
            return image


def _pixels_near(image: np.ndarray, color: tuple[int, ...], tolerance: int = 40) -> int:
    rgb = (image[..., :3] * 255 if image.dtype.kind == "f" else image[..., :3]).astype(int)
    return int(np.all(np.abs(rgb - np.array(color[:3])) <= tolerance, axis=-1).sum())


@pytest.mark.slow
def test_the_real_viewer_draws_a_simulated_recording_and_its_death_costs_no_decay(tmp_path: Path) -> None:
    port = _free_port()
    shot = tmp_path / "live-view.png"
    viewer_pid: int | None = None
    with virtual_display() as display:
        env = {k: v for k, v in os.environ.items() if k != "WAYLAND_DISPLAY"}
        env["DISPLAY"] = display
        # the viewer's own state (its blueprint for tankdaq, kept across its restarts) in this test's folder:
        # what an earlier viewer on this machine kept must not decide what this one draws
        env["XDG_DATA_HOME"] = str(tmp_path / "viewer-state")
        record = [
            str(Path(sys.executable).with_name("tankdaq")), "record", "--hull", "swath", "--port", "sim",
            "--draft", "T", "--angle", "8", "--sim-speed", "8", "--viewer", "spawn",
            "--viewer-port", str(port), "--out", str(tmp_path), "--events", "jsonl",
        ]  # fmt: skip
        said = tmp_path / "stderr.txt"
        with said.open("w") as err:
            proc = subprocess.Popen(record, stdout=subprocess.PIPE, stderr=err, text=True, env=env)
        seen: list[dict] = []
        try:
            events = _events(proc.stdout)
            listening = _wait_for(events, seen, _viewer_said("rerun viewer pid"))["text"]
            viewer_pid = int(listening.split("pid ")[1].split()[0])
            assert f"listening on 127.0.0.1:{port}" in listening  # bound to this machine only
            _wait_for(events, seen, _settled(1))  # the first decay and its final fit are sent

            from rerun.experimental import ViewerClient

            client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
            image = _screenshot_once_drawn(client, shot)
            assert image.shape[0] >= 400 and image.shape[1] >= 600
            assert image[..., :3].std() > 0.05, "the window is blank"
            assert _pixels_near(image, MEASURED_COLOR) > 500, "no measured angle/rate drawn"
            assert _pixels_near(image, MODEL_COLOR) > 500, "no fitted model drawn"

            os.kill(viewer_pid, signal.SIGKILL)  # the viewer crashes in the middle of the session
            _wait_for(events, seen, _viewer_said("the rerun viewer exited"))
            _wait_for(events, seen, _settled())  # the session goes on: a whole decay after the crash
            proc.send_signal(signal.SIGTERM)  # the operator ends the session (as Ctrl-C)
            while (event := events.get(timeout=240)) is not None:
                seen.append(event)
            assert proc.wait(timeout=60) in (0, 130), seen
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=30)
            if viewer_pid is not None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(viewer_pid, signal.SIGKILL)
    output = said.read_text()
    assert "Traceback" not in output and "Flush timed out" not in output
    mcaps = sorted(tmp_path.glob("*.mcap"))
    assert len(mcaps) >= 2, output
    for path in mcaps:
        with path.open("rb") as f:
            assert make_reader(f).get_summary() is not None, f"{path} was not finished"
