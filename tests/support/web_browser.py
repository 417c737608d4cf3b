"""A recorder with ``--viewer web`` and a real browser on its page: what tests/viz/test_web_viewer.py and
bench/bench_web_memory.py share.

The recorder is ``tankdaq record`` (or ``session``) in a process of its own, with ``--events jsonl``: its
typed events (the viewer's address, each release and settle) are read on a thread and waited for, each
wait bounded and failing with what it said (its printed lines, read on another). The browser is Debian's
Chromium, headless, through playwright, drawing WebGL in software (SwiftShader): every page costs CPU while
it draws, so the pages are small where only the data's arrival is checked, and each is closed once
checked. What a page holds is read from the viewer
itself: ``window._handle.save_recording()`` (the web viewer's own handle) gives its active recording as
.rrd bytes, read back with rerun's ``RrdReader``.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = Path("/usr/bin/chromium")
#: WebAssembly and WebGL in headless Chromium without a GPU: SwiftShader through ANGLE.
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-dev-shm-usage",
]
#: The browsers are started at the lowest priority, where a tablet draws on its own. It is no bound: Chromium
#: (as root) puts its browser and GPU processes back at nice -8, and each browser runs in a session of its
#: own, which the kernel's autogroups give a share of the CPU equal to the recorder's session. So the
#: recorder on the same machine does get busy; the simulated device keeps streaming in a process of its own
#: (device/simulator/process.py), as a sensor is hardware.
NICE = 19
PHONE = {"width": 390, "height": 844}
TABLET = {"width": 820, "height": 1180}
#: A page that must only be served the data (each one drawn large costs the phone and the tablet).
SMALL = {"width": 240, "height": 240}
#: The simulated device's clock against the wall's where a page must follow a decay as it happens: slow
#: enough that a page drawn in software keeps up, fast enough that a decay takes seconds.
WATCHED_SPEED = "2"
#: Where nobody watches a decay as it happens (the memory's count, a recording's content): as fast as the
#: simulator goes.
FAST_SPEED = "8"
#: The longest a page is waited for (its WebAssembly loaded and a decay taken in, on a loaded machine).
PAGE_TIMEOUT_S = 120.0
#: The longest a recorder's line is waited for.
LINE_TIMEOUT_S = 120.0

#: The active recording of the page as base64 .rrd bytes; null before the viewer runs or has a recording.
SAVED_JS = """() => {
  const handle = window._handle;
  if (!handle) return null;
  let bytes;
  try { bytes = handle.save_recording(); } catch (e) { return null; }
  let text = '';
  for (let i = 0; i < bytes.length; i += 32768) {
    text += String.fromCharCode.apply(null, bytes.subarray(i, i + 32768));
  }
  return btoa(text);
}"""
#: The size of the page's recording once it differs from ``last`` (a polled wait for a change).
CHANGED_JS = """(last) => {
  const handle = window._handle;
  if (!handle) return false;
  try { const n = handle.save_recording().length; return n !== last ? n : false; } catch (e) { return false; }
}"""


def free_ports(count: int) -> list[int]:
    """Ports free on 127.0.0.1 now (each chosen by the kernel)."""
    sockets = [socket.socket() for _ in range(count)]
    try:
        for sock in sockets:
            sock.bind(("127.0.0.1", 0))
        return [sock.getsockname()[1] for sock in sockets]
    finally:
        for sock in sockets:
            sock.close()


class RunningTankdaq:
    """``tankdaq ARGS`` (given ``--events jsonl``) in a process of its own: its events (stdout, one JSON
    object a line) and its printed lines (stderr, for people and for a failure's message) collected on
    threads of their own; ``wait_event`` waits for one. Used as a context manager: stopped at the end
    (Ctrl-C, killed if that hangs), whatever happened."""

    def __init__(
        self,
        args: list[str],
        cwd: Path,
        stdin: int | None = subprocess.DEVNULL,
        on_event: Callable[[dict[str, Any]], None] = lambda _event: None,
    ) -> None:
        self.on_event = on_event  # called on the reading thread as each event comes (a memory sample)
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
        self.process = subprocess.Popen(
            [str(Path(sys.executable).with_name("tankdaq")), *args],
            cwd=cwd,
            stdin=stdin,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        self.events: list[dict[str, Any]] = []
        self.lines: list[str] = []
        self._heard = threading.Condition()
        self._readers = [
            threading.Thread(target=self._read_events, daemon=True),
            threading.Thread(target=self._read_lines, daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    def __enter__(self) -> RunningTankdaq:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _read_events(self) -> None:
        assert self.process.stdout is not None
        for text in self.process.stdout:
            event = json.loads(text)
            self.on_event(event)
            with self._heard:
                self.events.append(event)
                self._heard.notify_all()
        with self._heard:
            self._heard.notify_all()  # the end: a waiter stops waiting

    def _read_lines(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            with self._heard:
                self.lines.append(line.rstrip("\n"))

    def said(self) -> str:
        with self._heard:
            return "\n".join(self.lines)

    def count(self, kind: str) -> int:
        """How many ``kind`` events it said so far."""
        with self._heard:
            return sum(1 for event in self.events if event["event"] == kind)

    def wait_event(self, kind: str, timeout_s: float = LINE_TIMEOUT_S, **values: Any) -> dict[str, Any]:
        """The first ``kind`` event holding ``values``, waited for; fails with what it said when none came."""
        found: list[dict[str, Any]] = []

        def match() -> bool:
            found[:] = [e for e in self.events if e["event"] == kind and e.items() >= values.items()][:1]
            return bool(found) or not self._readers[0].is_alive()

        with self._heard:
            self._heard.wait_for(match, timeout_s)
        if not found:
            ended = "it ended" if not self._readers[0].is_alive() else f"none in {timeout_s:g} s"
            pytest.fail(f"tankdaq said no {kind} event {values} ({ended}); it said:\n{self.said()}")
        return found[0]

    def release_at(self, run: int) -> float:
        """The device time of run ``run``'s release, waited for."""
        return float(self.wait_event("released", run=run)["t_s"])

    @property
    def url(self) -> str:
        return str(self.wait_event("viewer_address")["url"])

    def interrupt(self, timeout_s: float = LINE_TIMEOUT_S) -> int:
        """Ctrl-C (SIGINT), then its exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
        return self.finish(timeout_s)

    def finish(self, timeout_s: float = LINE_TIMEOUT_S) -> int:
        """Its exit code once it ends by itself; fails (it is then stopped) after ``timeout_s``."""
        try:
            code = self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            pytest.fail(f"tankdaq did not end in {timeout_s:g} s; it said:\n{self.said()}")
        for reader in self._readers:
            reader.join(5.0)
        return code

    def stop(self) -> None:
        """End it if it still runs: Ctrl-C (its files closed, its server ended), killed if that hangs."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(60)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


@contextlib.contextmanager
def chromium() -> Iterator[Any]:
    """Debian's Chromium, headless, through playwright, at the lowest priority (``NICE``); closed (its
    processes ended) at the end. Skips with the reason where it or playwright is missing."""
    if not CHROMIUM.is_file():
        pytest.skip("no /usr/bin/chromium (make report-test-deps installs Debian's chromium)")
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="playwright is not installed (the test extra)"
    )
    with tempfile.TemporaryDirectory() as folder, sync_api.sync_playwright() as play:
        niced = Path(folder) / "chromium"
        niced.write_text(f'#!/bin/sh\nexec nice -n {NICE} {CHROMIUM} "$@"\n')
        niced.chmod(0o755)
        browser = play.chromium.launch(executable_path=str(niced), args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()


def new_page(browser: Any, size: dict[str, int], url: str) -> Any:
    """A page of its own (its own context: closing it ends its drawing) at ``size`` on ``url``."""
    page = browser.new_context(viewport=size, device_scale_factor=1).new_page()
    page.set_default_timeout(PAGE_TIMEOUT_S * 1000)
    page.goto(url)
    return page


@contextlib.contextmanager
def own_chromium(url: str) -> Iterator[subprocess.Popen[bytes]]:
    """A headless Chromium of its own on ``url`` (a small window), to be killed; ended at the end."""
    browser = subprocess.Popen(
        [
            "nice",
            "-n",
            str(NICE),
            str(CHROMIUM),
            "--headless=new",
            "--window-size=240,240",
            *CHROMIUM_ARGS,
            url,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        yield browser
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(browser.pid, signal.SIGKILL)
        browser.wait()


@dataclass
class Shown:
    """What a page's viewer holds of its active recording: per entity, its chunks as record batches."""

    entities: dict[str, list[Any]]

    def scalars(self, entity: str) -> tuple[np.ndarray, np.ndarray]:
        """Times (s on the device's clock) and first values of an entity's scalars."""
        times: list[float] = []
        values: list[float] = []
        for batch in self.entities.get(entity, []):
            names = batch.schema.names
            column = next((n for n in names if n.endswith(":scalars")), None)
            if "t" not in names or column is None:  # its style (static), or a clear between decays
                continue
            times += [float(t.value) / 1e9 for t in batch.column("t")]
            values += [float(row[0]) for row in batch.column(column).to_pylist()]
        order = np.argsort(times, kind="stable")
        return np.asarray(times)[order], np.asarray(values)[order]

    def texts(self, entity: str) -> list[tuple[float, str]]:
        """An entity's texts with their times (0 for a static one), in time order."""
        found: list[tuple[float, str]] = []
        for batch in self.entities.get(entity, []):
            column = next((n for n in batch.schema.names if n.endswith(":text")), None)
            if column is None:
                continue
            stamps = (
                [float(t.value) / 1e9 for t in batch.column("t")]
                if "t" in batch.schema.names
                else [0.0] * batch.num_rows
            )
            for stamp, value in zip(stamps, batch.column(column).to_pylist(), strict=True):
                if value:
                    found.append((stamp, str(value[0] if isinstance(value, list) else value)))
        return sorted(found, key=lambda item: item[0])

    def releases(self) -> list[float]:
        """The times (device s) of the releases in the Events panel, in order."""
        return [t for t, text in self.texts("/events") if text.startswith("release:")]

    def text(self, entity: str) -> str:
        """The newest text of a TextDocument entity ("" when none)."""
        said = self.texts(entity)
        return said[-1][1] if said else ""

    def fits(self) -> list[str]:
        return sorted(e for e in self.entities if e.startswith("/angle/fits/"))


def shown(page: Any) -> Shown | None:
    """The page's active recording, read back with rerun's reader; None before it has one."""
    from rerun.chunk import RrdReader

    encoded = page.evaluate(SAVED_JS)
    if not encoded:
        return None
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "page.rrd"
        path.write_bytes(base64.b64decode(encoded))
        reader = RrdReader(path)
        if not reader.recordings():
            return None
        entities: dict[str, list[Any]] = {}
        for chunk in reader.stream().to_chunks():
            entities.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return Shown(entities)


def wait_shown(
    page: Any, holds: Callable[[Shown], bool], what: str, timeout_s: float = PAGE_TIMEOUT_S
) -> Shown:
    """Wait (the page polled for a change of its recording, once a second) until what it shows
    ``holds``; fails after ``timeout_s`` saying ``what`` it waited for and what it held."""
    from playwright.sync_api import TimeoutError as PageTimeout

    deadline = time.monotonic() + timeout_s
    last: int | None = None
    seen: Shown | None = None
    while True:
        left_ms = (deadline - time.monotonic()) * 1000
        try:
            if left_ms <= 0:
                raise PageTimeout("past the deadline")
            changed = page.wait_for_function(CHANGED_JS, arg=last, polling=1000, timeout=left_ms)
        except PageTimeout:
            held = "nothing" if seen is None else f"entities {sorted(seen.entities)[:12]}"
            pytest.fail(
                f"the page at {page.viewport_size} did not show {what} in {timeout_s:g} s; it held {held}"
            )
        last = changed.json_value()
        seen = shown(page)
        if seen is not None and holds(seen):
            return seen


def colour_pixels(png: bytes, colour: tuple[int, int, int], tolerance: int = 40) -> int:
    """How many pixels of a screenshot are within ``tolerance`` of ``colour`` (per channel)."""
    from PIL import Image

    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return int((np.abs(image - np.array(colour)).max(axis=2) <= tolerance).sum())


def resident_mb(pid: int) -> float:
    """The resident set of a process (MB), from /proc."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def children(pid: int) -> list[int]:
    """The processes started by ``pid`` (the view process, the web viewer's server)."""
    found: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError):
            found += [int(c) for c in (task / "children").read_text().split()]
    return found


def listening_ports(pid: int) -> set[int]:
    """The TCP ports process ``pid`` itself listens on (its sockets in /proc/net/tcp, tcp6)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        with contextlib.suppress(OSError):
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    ports = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for row in Path(table).read_text().splitlines()[1:]:
            fields = row.split()
            if fields[3] == "0A" and fields[9] in inodes:  # LISTEN
                ports.add(int(fields[1].rsplit(":", 1)[1], 16))
    return ports


def record_args(
    out: Path,
    runs: int | None,
    ports: list[int],
    viewer: str = "web",
    bind: str | None = "127.0.0.1",
    speed: str = FAST_SPEED,
) -> list[str]:
    """``tankdaq record`` on the simulated MTi-G (seed 0), ``runs`` decays (None: until stopped), the web
    viewer on ``bind`` (None: the default, the machine's network address) at ``ports`` (data, page)."""
    args = ["record", "--port", "sim", "--draft", "T", "--angle", "8", "--hull", "swath", "--out", str(out)]
    args += ["--seed", "0", "--sim-speed", speed, "--viewer", viewer, "--events", "jsonl"]
    args += ["--runs", str(runs)] if runs is not None else []
    if viewer.startswith("web"):
        args += ["--viewer-port", str(ports[0]), "--viewer-web-port", str(ports[1])]
        args += ["--viewer-bind", bind] if bind is not None else []
    return args


def memory_over_decays(
    out: Path, decays: int, on_decay: Callable[[int], None] = lambda _n: None
) -> dict[str, Any]:
    """``decays`` simulated decays recorded with ``--viewer web`` and a browser (a small page) on the page
    all along; the resident set of tankdaq (and of it with its view process and server) at each
    decay's settle. The page is checked to have been served a fitted decay at the end."""
    sampler = SettleMemory(on_decay)
    with RunningTankdaq(record_args(out, decays, free_ports(2)), out.parent, on_event=sampler) as recorder:
        sampler.pid = recorder.process.pid
        with chromium() as browser:
            page = new_page(browser, SMALL, recorder.url)
            recorder.wait_event("settled", timeout_s=LINE_TIMEOUT_S * decays, run=decays)
            wait_shown(page, lambda seen: bool(seen.fits()), "a fitted decay")
            page.context.close()
        assert recorder.finish() == 0, recorder.said()
    assert len(sampler.own) == decays, recorder.said()
    return {"rss_mb": sampler.own, "rss_with_children_mb": sampler.tree}


class SettleMemory:
    """The resident set of a recorder (``pid``; and of it with its view process and server) as each of
    its decays settles: its ``settled`` event heard (``RunningTankdaq``'s ``on_event``)."""

    def __init__(self, on_decay: Callable[[int], None] = lambda _n: None) -> None:
        self.pid: int | None = None
        self.own: list[float] = []
        self.tree: list[float] = []
        self.on_decay = on_decay

    def __call__(self, event: dict[str, Any]) -> None:
        if self.pid is None or event["event"] != "settled":
            return
        with contextlib.suppress(OSError):  # ended meanwhile: nothing to measure
            self.own.append(resident_mb(self.pid))
            self.tree.append(self.own[-1] + sum(resident_mb(c) for c in children(self.pid)))
            self.on_decay(len(self.own))
