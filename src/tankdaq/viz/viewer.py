"""The rerun viewer as a process: which viewer, whether a window can open, the modes a view takes, and
starting one that outlives tankdaq for the operator.

Kept apart from the view (``viz.live``) and its feed thread (``viz.view_feed``): nothing here logs data.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from urllib.parse import urlsplit

from ..errors import InputError
from ..samples import AXIS_FIELDS

URL_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
MODES = ("spawn", "save", "none", "web", "web+save")  # web: viz.web_viewer

#: A spawned viewer and its gRPC server listen here unless the operator asks otherwise.
DEFAULT_BIND = "127.0.0.1"
#: A spawned viewer must be listening within this long.
SPAWN_TIMEOUT_S = 20.0


def rerun_executable() -> str | None:
    """The viewer of the installed rerun-sdk: its ``rerun_cli`` binary, else beside this Python, else PATH.

    The binary inside ``rerun_cli`` is found wherever tankdaq runs from (``.venv/bin/tankdaq`` with
    the venv not on PATH), and it is the viewer process itself, not a Python wrapper around it.
    """
    try:
        import rerun_cli
    except ImportError:
        bundled = None
    else:
        bundled = Path(rerun_cli.__file__).with_name("rerun.exe" if sys.platform == "win32" else "rerun")
    beside = Path(sys.executable).parent / "rerun"
    for candidate in (bundled, beside):
        if candidate is not None and candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    return shutil.which("rerun")


def display_available() -> bool:
    """True when a window can be opened: an X or Wayland display is named."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def default_viewer_mode() -> str:
    """``spawn`` when there is a display and a viewer to show on it, ``save`` (an .rrd) otherwise."""
    return "spawn" if display_available() and rerun_executable() else "save"


def describe_mode(mode: str, default: bool) -> str:
    """What ``record`` and ``replay`` say at start (a viewer note): which view, and how to choose another."""
    what = {
        "spawn": "spawn (a rerun window; an .rrd is saved as well)",
        "save": "save (an .rrd per decay; open it with rerun FILE.rrd)",
        "none": "none (no live view)",
        "web": "web (the web viewer for a tablet or phone, served from here)",
        "web+save": "web (the web viewer for a tablet or phone, served from here) and an .rrd per decay",
    }.get(mode, f"stream to {mode}")
    chosen = (
        f"default ({'a display is available' if mode == 'spawn' else 'no display'}); choose with --viewer"
        if default
        else "as asked"
    )
    return f"{what}, {chosen}"


def check_mode(mode: str) -> str:
    """Refuse a viewer mode that is neither spawn, save, none, web (``web,save`` with an .rrd) nor a rerun
    URL (exit 2 at the CLI)."""
    if sorted(mode.replace("+", ",").split(",")) == ["save", "web"]:
        return "web+save"
    if mode in MODES:
        return mode
    example = "rerun+http://127.0.0.1:9876/proxy"
    if mode.startswith(URL_SCHEMES):
        try:  # urlsplit checks the brackets of an IPv6 host; .port the port's digits and range
            parts = urlsplit(mode)
            parts.port  # noqa: B018 (the check is the parse)
        except ValueError as exc:
            raise InputError(f"viewer URL {mode!r} not understood ({exc}); write it like {example}") from None
        if not parts.hostname:
            raise InputError(f"viewer URL {mode!r} names no host; write it like {example}")
        return mode
    raise InputError(
        f"viewer mode {mode!r} not understood: use spawn, save, web, web,save, none, or a URL like {example}"
    )


def url_listening(url: str) -> bool:
    """True when something accepts connections at a rerun URL's host and port."""
    parts = urlsplit(url)
    return listening(parts.hostname or "127.0.0.1", parts.port or 9876)


def listening(host: str, port: int) -> bool:
    """True when something accepts connections at ``host:port`` (a wildcard bind means this machine)."""
    address = "127.0.0.1" if host in ("0.0.0.0", "::", "") else host
    with socket.socket(socket.AF_INET6 if ":" in address else socket.AF_INET) as probe:
        probe.settimeout(0.5)
        return probe.connect_ex((address, port)) == 0


def spawn_viewer(
    bind: str, port: int, on_note: Callable[[str], None]
) -> tuple[subprocess.Popen[bytes] | None, str | None]:
    """Start the viewer bound to ``bind`` unless one already listens on ``port``.

    Returns (the process started, the URL to stream to); the URL is None when no viewer came up, and
    each outcome is one line to ``on_note``.
    """
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    if listening(bind, port):
        on_note(f"a viewer already listens on port {port}: the view goes there")
        return None, url
    executable = rerun_executable()
    if executable is None:
        on_note("no rerun viewer found (is rerun-sdk installed?): saving an .rrd instead")
        return None, None
    process = subprocess.Popen(
        [executable, "--bind", bind, "--port", str(port), "--hide-welcome-screen", "--expect-data-soon"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # the window outlives tankdaq for the operator; Ctrl-C spares it
        env={**os.environ, "RERUN_APP_ONLY": "true"},
    )
    deadline = time.monotonic() + SPAWN_TIMEOUT_S
    while process.poll() is None and time.monotonic() < deadline:
        if listening(bind, port):
            on_note(f"rerun viewer pid {process.pid} listening on {bind}:{port}")
            return process, url
        time.sleep(0.05)
    code = process.poll()
    if code is None:
        process.kill()
        process.wait(timeout=10)
    why = f"exited with code {code}" if code is not None else f"did not listen in {SPAWN_TIMEOUT_S:g} s"
    on_note(f"the rerun viewer {why} (no working display?): saving an .rrd instead")
    return process, None


def note_to_stderr(line: str) -> None:
    """A view's note where nobody listens for them: one line on stderr."""
    print(f"viewer: {line}", file=sys.stderr)


def settle_mode(mode: str, axis: str, on_note: Callable[[str], None]) -> str:
    """The view mode in effect: ``mode`` and ``axis`` checked (one line each, ``InputError``), and
    spawn without a display already save, said in one note."""
    mode = check_mode(mode)
    if axis not in AXIS_FIELDS:
        raise InputError(f"axis {axis!r} not understood; use one of: {', '.join(AXIS_FIELDS)}")
    if mode == "spawn" and not display_available():
        on_note("no display (DISPLAY and WAYLAND_DISPLAY unset): no window; saving an .rrd instead")
        return "save"
    return mode
