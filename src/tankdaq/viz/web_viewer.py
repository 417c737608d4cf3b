"""The web viewer served from the recorder (``--viewer web``): rerun's data server and its web viewer
(HTML and WebAssembly from the installed rerun-sdk, no internet needed), bound to the address the
operator names, and the address a tablet or phone opens, with its QR code for the terminal.

rerun's Python ``serve_grpc`` and ``serve_web_viewer`` listen on every interface (0.0.0.0) and cannot
be told otherwise; the ``rerun`` binary of the same wheel takes ``--bind``. So the server is that binary
(``--serve-web``, no window), a child process of the recorder for the whole run: the decay views
(``viz.view_process``, replaced every so many decays) stream to it, all into one recording
(``WebStream``: rerun 0.41's web viewer shows a page that connects to a server holding several
recordings none of them), and a browser that connects, late or again, gets what it holds
(``--server-memory-limit``: the oldest data go first). It only serves: nothing
a browser does reaches the recorder. The address rerun itself prints says ``localhost``, useless on a
tablet: the one printed here is the machine's network address.
"""

from __future__ import annotations

import contextlib
import errno
import io
import ipaddress
import os
import signal
import socket
import subprocess
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Self
from urllib.parse import quote

from ..errors import InputError, TankdaqError
from .viewer import listening, rerun_executable

#: ``--viewer`` modes that serve the web viewer: alone, or with an .rrd beside each recording as well.
WEB_MODES = ("web", "web+save")
#: The data server's port (rerun's own default) and the web viewer's.
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090
#: What the data server keeps for a browser that connects late or reloads: some minutes of decays at the
#: web rate with their fits; beyond it the oldest go first (a day of decays never fills the PC).
SERVER_MEMORY_LIMIT = "96MB"
#: The web feed's rate: what a screen needs (the recording keeps every sample).
WEB_RATE_HZ = 50.0
#: prctl's option that has the kernel signal a child when its parent dies (linux/prctl.h).
PR_SET_PDEATHSIG = 1
#: The server must be listening within this long.
START_TIMEOUT_S = 20.0
#: The server's niceness: below the recorder's (and its view's) claim on the cores.
SERVER_NICE = 10
#: A documentation address (TEST-NET-2, RFC 5737; a unicast one: a broadcast needs SO_BROADCAST):
#: "connected" to by UDP, nothing is sent, and the socket's own address is then the one of the
#: interface the default route leaves by.
_PROBE = ("198.51.100.1", 9)


def is_web(mode: str | None) -> bool:
    """True for a ``--viewer`` mode that serves the web viewer."""
    return mode in WEB_MODES


def lan_address() -> str | None:
    """This machine's address on its network (the interface of the default route, else one its name
    resolves to), None when it has only loopback."""
    candidates: list[str] = []
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect(_PROBE)
        candidates.append(probe.getsockname()[0])
    with contextlib.suppress(OSError):
        infos = socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET, socket.SOCK_DGRAM)
        candidates += [str(info[4][0]) for info in infos]
    for address in candidates:
        ip = ipaddress.ip_address(address)
        if not (ip.is_loopback or ip.is_unspecified or ip.is_link_local):
            return address
    return None


def _wildcard(host: str) -> bool:
    return host in ("0.0.0.0", "::", "")


def settle_bind(bind: str | None, on_note: Callable[[str], None]) -> str:
    """The address the web viewer listens on: the one asked (checked: an address of this machine), else
    the machine's network address; with none, this machine only, said in one note."""
    if bind is None:
        found = lan_address()
        if found is None:
            on_note("no network address found (loopback only): the web viewer is on this machine only")
        return found or "127.0.0.1"
    try:
        ipaddress.ip_address(bind)
    except ValueError:
        raise InputError(f"--viewer-bind {bind!r} is not an IP address; give one like 192.168.1.20") from None
    with socket.socket(socket.AF_INET6 if ":" in bind else socket.AF_INET) as probe:
        try:
            probe.bind((bind, 0))
        except OSError:
            raise InputError(
                f"--viewer-bind {bind} is not an address of this machine (see `ip addr`); "
                "leave it out for the machine's network address"
            ) from None
    return bind


@dataclass(frozen=True)
class WebStream:
    """Where the views stream to: the data server's ``url`` and ``recording_id``, the one recording of
    the whole run (each view process, each decay, the session's panel: a page has one to show)."""

    url: str
    recording_id: str


@dataclass(frozen=True)
class WebAddress:
    """Where the web viewer listens: ``bind`` (an address of this machine, or a wildcard) and two ports."""

    bind: str
    grpc_port: int = DEFAULT_GRPC_PORT
    web_port: int = DEFAULT_WEB_PORT

    @property
    def host(self) -> str:
        """The host a tablet uses: the bound address, or the network address behind a wildcard."""
        return (lan_address() or "127.0.0.1") if _wildcard(self.bind) else self.bind

    @property
    def data_url(self) -> str:
        """The data server's address for the views that stream to it (this machine)."""
        host = "127.0.0.1" if _wildcard(self.bind) else self.bind
        return f"rerun+http://{_url_host(host)}:{self.grpc_port}/proxy"

    @property
    def tablet_url(self) -> str:
        """The page a browser opens: the web viewer, told where the data server is."""
        data = f"rerun+http://{_url_host(self.host)}:{self.grpc_port}/proxy"
        return f"http://{_url_host(self.host)}:{self.web_port}/?url={quote(data, safe='')}"

    def check_free(self) -> None:
        """Refuse, in one line, a port something else already listens on (before any device opens)."""
        if self.grpc_port == self.web_port:
            raise InputError(f"--viewer-port and --viewer-web-port are both {self.web_port}: give two ports")
        for port, flag in ((self.grpc_port, "--viewer-port"), (self.web_port, "--viewer-web-port")):
            with socket.socket(socket.AF_INET6 if ":" in self.bind else socket.AF_INET) as probe:
                # as the server binds: a port left in TIME_WAIT by the last run is free, a listener is not
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    probe.bind((self.bind, port))
                except OSError as exc:
                    why = (
                        "in use (another tankdaq or viewer?)"
                        if exc.errno == errno.EADDRINUSE
                        else exc.strerror
                    )
                    raise TankdaqError(
                        f"web viewer: port {port} on {self.bind} is {why}; choose another with {flag}"
                    ) from None


def _end_with_parent() -> None:
    """In the server's process before it runs (Linux): it gets SIGTERM when the recorder dies, even killed
    (a server left behind would hold the ports); and it yields the cores to the recorder (``SERVER_NICE``):
    pages that reload or many browsers make it busy, and a page served late costs nothing, a device starved
    of reads costs a decay."""
    with contextlib.suppress(OSError):
        os.nice(SERVER_NICE)
    with contextlib.suppress(OSError, AttributeError):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def qr_text(url: str) -> str:
    """The QR code of ``url`` in terminal characters (two rows of modules per line)."""
    import segno

    out = io.StringIO()
    segno.make(url, error="l").terminal(out=out, compact=True)
    return out.getvalue().rstrip("\n")


class WebServer:
    """rerun's data server and web viewer (the ``rerun`` binary, ``--serve-web``) as a child process,
    listening at ``address`` until ``close``."""

    def __init__(self, address: WebAddress, memory_limit: str = SERVER_MEMORY_LIMIT) -> None:
        self.address = address
        self.memory_limit = memory_limit
        self.process: subprocess.Popen[bytes] | None = None
        self.stream = WebStream(address.data_url, str(uuid.uuid4()))

    def start(self) -> Self:
        """Check the ports, start the server, wait until both ports listen; a failure is one line."""
        address = self.address
        address.check_free()
        executable = rerun_executable()
        if executable is None:
            raise TankdaqError("no rerun viewer found (is rerun-sdk installed?): use --viewer save")
        command = [
            executable, "--serve-web", "--bind", address.bind, "--port", str(address.grpc_port),
            "--web-viewer-port", str(address.web_port), "--server-memory-limit", self.memory_limit,
        ]  # fmt: skip
        self.process = subprocess.Popen(
            command,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # a Ctrl-C reaches the recorder, which ends the server after the decay
            env={**os.environ, "RERUN_APP_ONLY": "true"},
            preexec_fn=_end_with_parent,
        )
        deadline = time.monotonic() + START_TIMEOUT_S
        while self.process.poll() is None and time.monotonic() < deadline:
            if all(listening(address.bind, port) for port in (address.grpc_port, address.web_port)):
                return self
            time.sleep(0.05)
        code = self.process.poll()
        self.close()
        why = f"exited with code {code}" if code is not None else f"did not listen in {START_TIMEOUT_S:g} s"
        raise TankdaqError(f"the web viewer's server {why}; use --viewer save, or other ports")

    @property
    def pid(self) -> int | None:
        return None if self.process is None else self.process.pid

    def close(self) -> None:
        """Stop the server (browsers see the connection end; the recordings are the recorder's)."""
        process, self.process = self.process, None
        if process is None or process.poll() is not None:
            return
        process.terminate()
        try:
            process.wait(5.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()

    def __enter__(self) -> Self:
        return self if self.process is not None else self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
