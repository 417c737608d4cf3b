"""The simulated MTi-G of ``--port sim`` in a process of its own: a sensor does not share the recorder's
interpreter.

A ``SimulatedMTi`` thread in the recorder's process shares the interpreter lock and the recorder's share
of the CPU with the pipeline, the decoding, the live fit and the view's feed. On a busy host (browsers
drawing the web view in software, a test suite beside it) that thread wrote nothing for seconds, the
driver rightly took the device for gone, and a decay a real sensor would have delivered was lost.
``SimulatorProcess`` runs the ``SimulatedMTi`` in ``python -m tankdaq.device.simulator.process``, in a
session of its own (as the reader process: the kernel shares the CPU between sessions, and a Ctrl-C at
the terminal reaches only the recorder, which stops the device in order), and forwards the calls the
recorder and its tests make (``play``, ``unplug``, ``replug``, ``stall``, ``truth``, ``received``,
``baud``) over a socket pair, one at a time. The recorder's end closing (it died) stops the device and
removes its pty and links.
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

from ...errors import DeviceError, InputError
from ...physics.scenario import DecayScenario
from ...physics.truth import RunTruth
from .firmware import ReceivedMessage
from .mti import SimulatedMTi
from .pty_link import register_by_id, unregister_by_id
from .sources import RecordedSource

#: The longest the device process is waited for: started (an interpreter, numpy, the scenario computed)
#: or answering a call (``play`` computes the next scenario).
ANSWER_WAIT_S = 60.0
#: How long ``stop`` waits for the process to end before it is killed.
END_WAIT_S = 5.0

#: What the process does for each call: the device's method or property, on its own thread's terms.
CALLS: dict[str, Callable[..., Any]] = {
    "play": SimulatedMTi.play,
    "unplug": SimulatedMTi.unplug,
    "replug": SimulatedMTi.replug,
    "stall": SimulatedMTi.stall,
    "truth": lambda sim: sim.truth,
    "received": lambda sim: sim.received,
    "baud": lambda sim: sim.baud,
    "port": lambda sim: sim.port,
}


class SimulatorProcess:
    """``SimulatedMTi(scenario or source, speed, baud, seed, legacy)`` in a process of its own, from
    ``start`` until ``stop`` (a context manager). ``link`` (the stable pty link the driver opens) and
    ``by_id_dir`` (named in this process's ``TANKDAQ_SERIAL_BY_ID`` while it runs, so the driver finds a
    re-plugged device by its serial) are known once started; the rest is asked of the device."""

    def __init__(
        self,
        scenario: DecayScenario | None = None,
        *,
        source: RecordedSource | None = None,
        speed: float = 1.0,
        baud: int = 115200,
        seed: int = 0,
        legacy: bool = False,
    ) -> None:
        self._options: dict[str, Any] = {
            "scenario": scenario, "source": source, "speed": speed, "baud": baud, "seed": seed,
            "legacy": legacy,
        }  # fmt: skip
        self._lock = threading.Lock()  # one call at a time: a call's answer is the next message
        self._process: subprocess.Popen[bytes] | None = None
        self._conn: Connection | None = None
        self.link = self.by_id_dir = ""
        self._last: dict[str, Any] = {}  # what the device said as it stopped: its ``received``, its ``truth``

    def __enter__(self) -> SimulatorProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def pid(self) -> int | None:
        return self._process.pid if self._process is not None else None

    def start(self) -> SimulatorProcess:
        """Start the process and wait until the device is plugged in (its pty and links made)."""
        if self._process is not None:
            return self
        ours, theirs = socket.socketpair()
        with theirs:
            self._process = subprocess.Popen(
                [sys.executable, "-m", __name__, str(theirs.fileno())],
                pass_fds=(theirs.fileno(),),
                stdin=subprocess.DEVNULL,
                start_new_session=True,
            )
        self._conn = Connection(ours.detach())
        try:
            self._conn.send(self._options)
            self.link, self.by_id_dir = self._answer()
        except BaseException:
            self.stop()
            raise
        register_by_id(self.by_id_dir)
        return self

    def stop(self) -> None:
        """Stop the device (its pty and links removed) and the process; killed if it does not end."""
        with self._lock:
            process, conn, self._process, self._conn = self._process, self._conn, None, None
            if process is None or conn is None:
                return
            with contextlib.suppress(OSError, ValueError, EOFError):
                conn.send(("stop", ()))
                if conn.poll(END_WAIT_S):
                    self._last = conn.recv()[1]
            try:
                process.wait(END_WAIT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            finally:
                conn.close()
                if self.by_id_dir:
                    unregister_by_id(self.by_id_dir)

    # ---- the device's calls ----------------------------------------

    @property
    def port(self) -> str:
        """The current /dev/pts/N ("" unplugged)."""
        return str(self._call("port"))

    @property
    def baud(self) -> int:
        return int(self._call("baud"))

    @property
    def truth(self) -> list[RunTruth]:
        """The scenario's runs (``SimulatedMTi.truth``), also once stopped."""
        return list(self._call_or_last("truth"))

    @property
    def received(self) -> list[ReceivedMessage]:
        """Every message the host wrote (``SimulatedMTi.received``), also once stopped."""
        return list(self._call_or_last("received"))

    def play(self, scenario: DecayScenario) -> None:
        """Play ``scenario`` next on the same clock (``SimulatedMTi.play``)."""
        self._call("play", scenario)

    def unplug(self) -> None:
        self._call("unplug")

    def replug(self) -> None:
        self._call("replug")

    def stall(self, seconds: float) -> None:
        self._call("stall", seconds)

    def _call(self, name: str, *args: object) -> Any:
        with self._lock:
            if self._conn is None:
                raise DeviceError("the simulated MTi-G is not running")
            self._conn.send((name, args))
            return self._answer()

    def _call_or_last(self, name: str) -> Any:
        """``name`` asked of the device, or as it said it when it stopped."""
        return self._last[name] if self._conn is None and name in self._last else self._call(name)

    def _answer(self) -> Any:
        """The device process's answer to the last message; its refusal raised here, as it was raised."""
        assert self._conn is not None and self._process is not None
        try:
            if not self._conn.poll(ANSWER_WAIT_S):
                raise DeviceError(f"the simulated MTi-G did not answer in {ANSWER_WAIT_S:g} s")
            ok, value = self._conn.recv()
        except (EOFError, OSError) as exc:
            code = self._process.poll()
            raise DeviceError(f"the simulated MTi-G's process ended (exit code {code})") from exc
        if ok:
            return value
        refused, text = value
        raise (InputError if refused else DeviceError)(text)


# ---- the process itself ----------------------------------------


def _serve(conn: Connection) -> None:
    """Start the device as the first message says, then answer calls until ``stop`` or the recorder's end
    closes; the device is stopped either way."""
    try:
        sim = SimulatedMTi(**conn.recv()).start()
    except (EOFError, OSError):
        return
    except Exception as exc:  # a refusal (InputError) or a failure: said to the recorder, raised there
        conn.send((False, (isinstance(exc, InputError), str(exc))))
        return
    try:
        conn.send((True, (sim.link, sim.by_id_dir)))
        while True:
            name, args = conn.recv()
            if name == "stop":
                sim.stop()
                conn.send((True, {"received": sim.received, "truth": sim.truth}))
                return
            try:
                answer = (True, CALLS[name](sim, *args))
            except Exception as exc:
                answer = (False, (isinstance(exc, InputError), str(exc)))
            conn.send(answer)
    except (EOFError, OSError):
        return  # the recorder is gone: the device goes too
    finally:
        sim.stop()


def main(argv: list[str]) -> int:
    """The process: ``argv`` is this module and the socket's descriptor; exit code 0."""
    conn = Connection(int(argv[1]))
    try:
        _serve(conn)
    finally:
        conn.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
