"""The live view in a process of its own (``ViewProcess``), as the record daemon runs it all day.

rerun's SDK keeps a little of every recording made with it, in its own allocator and threads' heaps
(some 1 MB an hour at 400 Hz with the view saving, ``bench/bench_memory_day.py``), and a
native failure in it would take the process with it. Here a ``LiveView`` runs in a child process, fed
through a pipe by one thread of this process (``ViewFeed``: ``put`` never waits, sample blocks and
refits beyond the limit are dropped and counted, as the view's own thread does). Every
``RUNS_PER_PROCESS`` runs the child is let go (it finishes its last .rrd and exits) and a fresh one takes
the next run, so whatever rerun kept is given back whole. A child that dies costs one note; the next
run starts another. The child runs in a session of its own and ignores the terminal's signals: the
recorder decides when the view ends, and a recorder that dies leaves the child at the end of its pipe,
where it finishes its .rrd and exits.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable, Mapping, Sequence
from multiprocessing.connection import Connection
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol, Self

import numpy as np

from ..errors import InputError
from ..store.disk import RESERVE_BYTES
from .live import CLOSE_LIMIT_S, CLOSE_STALL_S, LiveView, unfinished_note
from .view_feed import QUEUE_LIMIT, SAVE_QUEUE_LIMIT, ViewFeed
from .viewer import DEFAULT_BIND, note_to_stderr, settle_mode
from .web_view import WebLiveView
from .web_viewer import WebStream, is_web

#: Runs one view process shows before a fresh one takes over (about an hour of decays at 35 s each;
#: what rerun keeps of so many runs is a megabyte or so).
RUNS_PER_PROCESS = 100

#: How much longer than its own bound on closing a view process is given before it is stopped.
CHILD_GRACE_S = 10.0

#: What a terminal or a service manager sends the whole process group; the child ignores them.
TERMINAL_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM, signal.SIGHUP})


class View(Protocol):
    """What the decay pipeline's view sink (``acquire.sinks.ViewSink``) needs of a live view: ``LiveView``
    (in this process) and ``ViewProcess`` (the same in a process of its own) both are one; mypy checks it
    where the record daemon and replay choose one."""

    mode: str
    axis: str
    rrd_path: Path | None
    rrd_reserve_bytes: int

    @property
    def dropped(self) -> int: ...

    def new_run(
        self,
        name: str = "decay",
        rrd_path: str | Path | None = None,
        terms: Sequence[str] | None = None,
        time_origin_s: float = 0.0,
    ) -> None: ...

    def log_samples(self, samples: np.ndarray) -> None: ...

    def log_fit(
        self,
        t: np.ndarray,
        predicted_angle: np.ndarray,
        predicted_rate: np.ndarray,
        coefficients: Mapping[str, float],
        ci95: Mapping[str, object] | None = None,
        t_fit: float | None = None,
        final: bool = False,
    ) -> None: ...

    def log_event(self, kind: str, message: str, t_s: float | None = None) -> None: ...

    def end_run(self) -> None: ...

    def close(self, stall_s: float = CLOSE_STALL_S, limit_s: float = CLOSE_LIMIT_S) -> None: ...


#: A message to the child: a ``LiveView`` method's name, its positional and keyword arguments.
Message = tuple[str, tuple[Any, ...], dict[str, Any]]


def serve_view(conn: Connection) -> None:
    """The child: a ``LiveView`` made with the options of the first message on ``conn``, driven by the
    messages after it until "close" or the end of the pipe; its notes go back on ``conn``, then
    ("closed", dropped updates), and the process ends there (it never returns)."""
    for number in TERMINAL_SIGNALS:
        signal.signal(number, signal.SIG_IGN)  # the recorder ends the view: it finishes its .rrd first
    sending = threading.Lock()  # the view's thread sends notes while this one may send too

    def send(message: tuple[str, object]) -> None:
        with sending, contextlib.suppress(OSError):  # a recorder gone: nobody to tell
            conn.send(message)

    view = None
    try:
        options = conn.recv()
        kind = WebLiveView if options.pop("web", False) else LiveView
        view = kind(on_note=lambda line: send(("note", line)), **options)
        while True:
            method, args, kwargs = conn.recv()
            if method == "close":
                break
            if method == "new_run":
                view.axis = kwargs.pop("axis")
            getattr(view, method)(*args, **kwargs)
    except (EOFError, OSError):
        pass  # the recorder is gone: finish what was shown
    finally:
        if view is not None:
            view.close()
            send(("closed", view.dropped))
        conn.close()
        # Out at once: the interpreter's own exit would run rerun's, which flushes every recording again
        # and waits without end on a viewer that stalled (the view's close above is bounded and said so).
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(0)


class _Child:
    """One view process, the pipe to it and the thread that hands its notes on.

    A plain ``python -m tankdaq.viz.view_process`` (not multiprocessing's spawn, which would import the
    user's own script again in the child), in a session of its own so that a Ctrl-C or a hang-up at the
    terminal reaches only the recorder, which then ends the view in order."""

    def __init__(self, options: dict[str, Any], on_note: Callable[[str], None]) -> None:
        ours, theirs = socket.socketpair()
        with theirs:
            self.process = subprocess.Popen(
                [sys.executable, "-m", __name__, str(theirs.fileno())],
                pass_fds=(theirs.fileno(),),
                stdin=subprocess.DEVNULL,
                start_new_session=True,
            )
        self.conn = Connection(ours.detach())
        self.runs = 0
        self.dropped = 0
        self._on_note = on_note
        self.send(options)  # the child's LiveView settings: its first message
        self._listener = threading.Thread(target=self._listen, name="tankdaq-view-notes", daemon=True)
        self._listener.start()

    def alive(self) -> bool:
        return self.process.poll() is None

    def _listen(self) -> None:
        while True:
            try:
                kind, value = self.conn.recv()
            except (EOFError, OSError):  # the child closed its end: it is ending; reaped at once
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self.process.wait(CHILD_GRACE_S)
                return
            if kind == "note":
                self._on_note(str(value))
            elif kind == "closed":
                self.dropped = int(str(value))

    def send(self, message: Message | dict[str, Any]) -> bool:
        """False when the child is gone (its pipe broken)."""
        try:
            self.conn.send(message)
        except (OSError, ValueError):
            return False
        return True

    def finish(self, timeout_s: float) -> bool:
        """Ask the child to end, wait for it (at most ``timeout_s``), stop it if it did not; True if
        it ended by itself."""
        self.send(("close", (), {}))
        try:
            self.process.wait(timeout_s)
            ended = True
        except subprocess.TimeoutExpired:
            ended = False
            self.process.kill()
            self.process.wait()
        self._listener.join(1.0)
        self.conn.close()
        return ended


class ViewProcess:
    """``LiveView``'s calls (``new_run``, ``log_samples``, ``log_fit``, ``log_event``, ``end_run``,
    ``close``), the view itself in a child process replaced every ``runs_per_process`` runs (see the
    module docstring). ``mode`` is spawn, save, a rerun URL (spawn without a display falls back to
    save here, at once), or web (``WebLiveView``s streaming to ``web``, the recorder's web viewer
    server's one recording); the other settings are ``LiveView``'s."""

    def __init__(
        self,
        mode: str,
        axis: str = "roll",
        terms: Sequence[str] = (),
        spawn_port: int = 9876,
        bind: str = DEFAULT_BIND,
        on_note: Callable[[str], None] | None = None,
        rrd_reserve_bytes: int = RESERVE_BYTES,
        runs_per_process: int = RUNS_PER_PROCESS,
        web: WebStream | None = None,
    ) -> None:
        if runs_per_process < 1:
            raise InputError(f"runs_per_process {runs_per_process}: give 1 or more")
        self.on_note = on_note or note_to_stderr
        self.mode = settle_mode(mode, axis, self.on_note)
        self.axis = axis
        self.terms = tuple(terms)
        self.rrd_reserve_bytes = rrd_reserve_bytes
        self.runs_per_process = runs_per_process
        self.rrd_path: Path | None = None
        self.web = web if is_web(self.mode) else None  # the web viewer's server streamed to (web mode)
        self._options: dict[str, Any] = {"mode": self.mode, "spawn_port": spawn_port, "bind": bind}
        if is_web(self.mode):
            if web is None:
                raise InputError("viewer mode web needs the web viewer's server (viz.web_viewer.WebServer)")
            self._options |= {"mode": web.url, "web": True, "recording_id": web.recording_id}
        self._options["rrd_reserve_bytes"] = rrd_reserve_bytes
        self._child: _Child | None = None  # touched by the feed's thread only
        self._retired: list[_Child] = []
        self._children_dropped = 0
        self._gone_noted = False
        limit = SAVE_QUEUE_LIMIT if self.mode == "save" else QUEUE_LIMIT
        self._feed = ViewFeed(on_error=self._failed, limit=limit)
        self.processes_started = 0
        # started now, before the device opens (and a window with it), not at the first release: its
        # start-up (a second of CPU: Python, numpy, rerun) must not fall on a decay's first seconds
        self._feed.put(self._start_child, droppable=False)

    @property
    def dropped(self) -> int:
        """Updates dropped because the view fell behind (the MCAP has them all)."""
        return self._feed.dropped + self._children_dropped

    @property
    def pids(self) -> list[int]:
        """The view processes started and not yet reaped (the current one last)."""
        return [child.process.pid for child in self._children()]

    def wait_idle(self, stall_s: float, limit_s: float | None = None) -> bool:
        """Wait until every call so far has been handed to a view process (as ``ViewFeed.wait_idle``)."""
        return self._feed.wait_idle(stall_s, limit_s)

    def new_run(
        self,
        name: str = "decay",
        rrd_path: str | Path | None = None,
        terms: Sequence[str] | None = None,
        time_origin_s: float = 0.0,
    ) -> None:
        """As ``LiveView.new_run``; a view process that has died is replaced first (with a note)."""
        if terms is not None:
            self.terms = tuple(terms)
        self.rrd_path = None if rrd_path is None else Path(rrd_path)
        kwargs = {"name": name, "rrd_path": self.rrd_path, "terms": self.terms, "axis": self.axis}
        self._feed.put(lambda: self._start_run({**kwargs, "time_origin_s": float(time_origin_s)}), False)

    def log_samples(self, samples: np.ndarray) -> None:
        """As ``LiveView.log_samples`` (dropped when the view is behind)."""
        if samples.size:
            self._put("log_samples", (samples.copy(),), droppable=True)

    def log_fit(
        self,
        t: np.ndarray,
        predicted_angle: np.ndarray,
        predicted_rate: np.ndarray,
        coefficients: Mapping[str, float],
        ci95: Mapping[str, object] | None = None,
        t_fit: float | None = None,
        final: bool = False,
    ) -> None:
        """As ``LiveView.log_fit`` (a refit dropped when the view is behind, the final fit never)."""
        args = (np.array(t, dtype=float), np.array(predicted_angle), np.array(predicted_rate))
        self._put("log_fit", (*args, dict(coefficients), dict(ci95 or {}), t_fit, final), droppable=not final)

    def log_event(self, kind: str, message: str, t_s: float | None = None) -> None:
        """As ``LiveView.log_event``."""
        self._put("log_event", (kind, message, t_s), droppable=False)

    def log_panel(self, markdown: str, t_s: float) -> None:
        """As ``WebLiveView.log_panel`` (web mode only; dropped when the view is behind)."""
        self._put("log_panel", (markdown, t_s), droppable=True)

    def end_run(self) -> None:
        """As ``LiveView.end_run`` (returns at once). A view process that has shown its
        ``runs_per_process`` runs is replaced now, between decays, while the model rests."""
        self._feed.put(self._end_run, droppable=False)

    def close(self, stall_s: float = CLOSE_STALL_S, limit_s: float = CLOSE_LIMIT_S) -> None:
        """End the view: every queued update sent, each view process finished (its .rrd complete) or,
        stuck for ``stall_s`` or past ``limit_s``, stopped with a note. A spawned viewer stays open."""
        if not self._feed.stop(stall_s, limit_s):
            self.on_note(
                unfinished_note("the view stopped unfinished; the last .rrd may be cut", stall_s, limit_s)
            )
        children, self._child, self._retired = self._children(), None, []
        for child in children:  # each bounds its own end and says so: this is the backstop
            if not child.finish(limit_s + CHILD_GRACE_S):
                self.on_note(f"the view process did not end in {limit_s + CHILD_GRACE_S:g} s: stopped")
            self._children_dropped += child.dropped

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _children(self) -> list[_Child]:
        """The view processes not yet reaped: those let go, then the current one."""
        return [*self._retired, *([self._child] if self._child is not None else [])]

    # -- the feed's thread ------------------------------------------------------------------------------

    def _put(self, method: str, args: tuple[Any, ...], droppable: bool) -> None:
        self._feed.put(lambda: self._send((method, args, {})), droppable)

    def _start_run(self, kwargs: dict[str, Any]) -> None:
        child = self._child
        if child is None or not child.alive():
            if child is not None:
                self._note_gone(child)
            child = self._next_child()
        child.runs += 1
        self._send(("new_run", (), kwargs))

    def _end_run(self) -> None:
        self._send(("end_run", (), {}))
        if self._child is not None and self._child.runs >= self.runs_per_process:
            self._next_child()

    def _start_child(self) -> None:
        self._next_child()  # with spawn, its LiveView opens the viewer as it starts

    def _next_child(self) -> _Child:
        """A fresh view process; the current one (if any) is asked to finish and reaped at close."""
        old = self._child
        if old is not None:
            old.send(("close", (), {}))
            self._retired.append(old)
        for ended in [child for child in self._retired if not child.alive()]:
            self._retired.remove(ended)
            ended.finish(0.0)
            self._children_dropped += ended.dropped
        self._child = _Child(self._options, self.on_note)
        self.processes_started += 1
        self._gone_noted = False
        return self._child

    def _send(self, message: Message) -> None:
        child = self._child
        if child is not None and not self._gone_noted and not child.send(message):
            self._note_gone(child)

    def _note_gone(self, child: _Child) -> None:
        if not self._gone_noted:
            self._gone_noted = True
            with contextlib.suppress(subprocess.TimeoutExpired):
                child.process.wait(1.0)
            code = child.process.returncode
            self.on_note(
                f"the view process ended (exit {code}); the recording goes on, the next decay starts another"
            )

    def _failed(self, exc: BaseException) -> None:
        self.on_note(f"view update failed ({exc}); the recording goes on")


if __name__ == "__main__":
    serve_view(Connection(int(sys.argv[1])))
