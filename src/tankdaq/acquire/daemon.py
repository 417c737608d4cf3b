"""The record daemon: device -> release detection -> one MCAP per decay, live fit and view.

It runs until ``runs`` decays are recorded or it is stopped: Ctrl-C, SIGTERM and SIGHUP (a
closed terminal or SSH session) all close the decay under way as a complete file (``stopped_by``
names the signal) that says it was stopped (``DecayEnd.STOPPED``: partial). A device that vanishes
mid-decay closes that file with what arrived (``DEVICE_LOST``), and the daemon waits for the device
to come back; an exception closes it as ``ERROR``. ``port="sim"`` starts the built-in
simulated MTi-G in-process on a pseudo-terminal, opened like hardware
(``device.factory.open_device``); ``port="sim:FILE.mcap"`` plays the device of that recording
(its raw bytes, at their pace) through the same pty. The decay pipeline is a ``DecayPipeline``
fitting each decay live, with the recording, the live view (``acquire.sinks``) and the listeners
given (``sinks``) as its sinks: ``acquire.recorder.Recorder``, which the daemon composes (and a guided
session too). What a person is told (the device, held, released, settled, gone, back,
stopping) is a typed event (``acquire.events``) every sink hears; the command line prints them.

Two threads: ``tankdaq-read`` (``acquire.read_thread``) only reads the device and queues the
blocks; the thread that called ``run`` takes them and runs the pipeline, its sinks, the files and
the callbacks, so an error there reaches the caller as before and the reads never wait for it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import RecordingError
from ..live.identifier import OnlineIdentifier
from ..records import DecayEnd
from .events import DecayOutcome, KeptOutcomes, Notice, Stopped, Stopping
from .recorder import DaemonStatus, Recorder, RecordSettings
from .signals import Phase, SignalStop
from .sinks import Sink

if TYPE_CHECKING:
    from ..device.simulator.process import SimulatorProcess
    from ..physics.scenario import DecayScenario

__all__ = ["DaemonStatus", "RecordDaemon", "RecordSettings"]


class RecordDaemon:
    """``run()`` records decays from the device until done; see the module docstring."""

    def __init__(
        self,
        settings: RecordSettings,
        on_status: Callable[[DaemonStatus], None] | None = None,
        sinks: Sequence[Sink] = (),  # more listeners: the printer of the events, a session's level check
        identifier: Callable[..., OnlineIdentifier] = OnlineIdentifier,  # the live fit's
        recorder: type[Recorder] = Recorder,  # a bench's own (its driver in place of ``open_device``)
    ) -> None:
        self._signals = SignalStop()
        self.recorder = recorder(settings, on_status, sinks, identifier, self._signals)

    @property
    def settings(self) -> RecordSettings:
        return self.recorder.settings

    @property
    def status(self) -> DaemonStatus:
        return self.recorder.status

    @property
    def outcomes(self) -> KeptOutcomes:
        """The newest ``KEPT_OUTCOMES`` decays' outcomes (``count``: how many there were)."""
        return self.recorder.outcomes

    @property
    def recordings(self) -> list[Path]:
        """The decay files this daemon wrote that exist: what a summary counts."""
        return self.recorder.recordings

    @property
    def simulator(self) -> SimulatorProcess | None:
        """The simulated sensor behind port ``sim`` once started (its ``truth``, ``unplug()``)."""
        return self.recorder.simulator

    def simulation_scenario(self) -> DecayScenario:
        """What the built-in simulated sensor plays (deterministic: its runs are the truth)."""
        return self.recorder.simulation_scenario()

    @property
    def stopped_by(self) -> str | None:
        """The signal that stopped ``run`` (SIGINT, SIGTERM, SIGHUP), None when it ran to its end."""
        return self._signals.stopped_by

    def stop(self) -> None:
        """Ask ``run`` to return once the blocks already read are fed (from a callback or another thread)."""
        self._signals.stop.set()

    def run(self) -> list[DecayOutcome]:
        """Record until ``runs`` decays are done or stopped; returns the outcomes of the newest
        ``KEPT_OUTCOMES`` decays (every decay's was a ``Settled`` event; ``outcomes.count``: how many)."""
        recorder, signals = self.recorder, self._signals
        ended = DecayEnd.ERROR  # how a decay under way ends: an exception, unless the loop ends as asked
        with signals.installed():
            try:
                recorder.open()
                recorder.feed(recorder.runs_done)
                ended = DecayEnd.STOPPED  # stopped (a signal, ``stop()``), or the runs done, none under way
            except KeyboardInterrupt:
                signals.stopped_by = signals.stopped_by or "SIGINT"
                ended = DecayEnd.STOPPED
            except RecordingError:
                stopped = "recording stopped: a file could not be written (files already closed are intact)"
                recorder.emit(Notice("recording", stopped))
                raise
            finally:
                with signals.during(Phase.CLOSING):  # a second Ctrl-C never cuts the file being closed
                    if signals.stopped_by:
                        recorder.emit(Stopping(signals.stopped_by))
                    recorder.close(ended)
            recorder.emit(Stopped(signals.stopped_by, recorder.outcomes.count))
        return list(recorder.outcomes)
