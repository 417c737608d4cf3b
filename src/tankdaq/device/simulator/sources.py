"""Where the simulated device's data comes from: the scripted physics, or frames a device really sent.

Like gpsfake's log source, a source only knows its frames and when each is due on the device
clock; the firmware decides whether the device measures, and the pty link carries the bytes.

- ``ScriptedSource``: a ``DecayScenario`` sampled at whatever rate the host configured, encoded
  by the output in force (MTData2 or legacy MTData), then still water for ever.
- ``RecordedSource``: the raw bytes of a recording's ``/xsens/raw`` channel (or a capture made
  on hardware), re-sent frame by frame at their recorded pace (SampleTimeFine), byte for byte:
  a recording made on a real MTi plays through the real driver as if the device were there.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
from collections.abc import Iterator, Sequence
from typing import Protocol

import numpy as np

from ...errors import InputError
from ...physics.scenario import DecayScenario
from ...physics.sensor import SensorModel
from ...physics.truth import RunTruth, still_trace
from ...xsens.column_decoder import DecodedBlock, decode_buffer
from ...xsens.control import MAX_FREQUENCY, PER_MESSAGE_OUTPUTS
from ...xsens.frame_scan import scan_frames
from ...xsens.timebase import MODULUS_32_BIT, MODULUS_ONE_DAY, TICKS_PER_SECOND, SampleTimeUnwrapper
from .identity import DeviceIdentity
from .output import DEVICE_RATES_HZ, Output


class FrameSource(Protocol):
    """Frames by index on the device clock (index 0 due at the source's origin)."""

    #: True: the frames start when the device starts measuring (a tape); False: at power-up (a clock).
    plays_from_measurement: bool
    #: The output configuration the frames carry whatever the host asks (None: the host configures it).
    configuration: list[tuple[int, int]] | None
    #: The device that sent them (None: the simulator's own).
    identity: DeviceIdentity | None

    @property
    def truth(self) -> list[RunTruth]:
        """The scripted runs (none for a recording: its truth is whatever happened in the tank)."""
        ...

    @property
    def start_ticks(self) -> int:
        """SampleTimeFine of frame 0."""
        ...

    def rate_hz(self, output: Output) -> float:
        """Nominal messages per second."""
        ...

    def due(self, device_s: float, output: Output, *, strict: bool = False) -> int:
        """How many frames are due at ``device_s`` (``strict``: due strictly before it)."""
        ...

    def time_s(self, index: int, output: Output) -> float:
        """When frame ``index`` is due (inf: never, the source has ended)."""
        ...

    def frames(self, start: int, stop: int, output: Output) -> list[bytes]:
        """Frames ``start`` .. ``stop - 1``, each as the bytes that go on the line."""
        ...


class ScenarioSamples:
    """Samples of the scenario by index at its rate, then still water for ever."""

    tail_block = 4096

    def __init__(self, scenario: DecayScenario) -> None:
        self.scenario = scenario
        self.samples, self.trace = scenario.samples()
        self._sensor: SensorModel = scenario.sensor()
        self._tail_start = -1
        self._tail = self.samples[:0]

    @property
    def rate_hz(self) -> float:
        return self.scenario.rate_hz

    @property
    def truth(self) -> list[RunTruth]:
        return self.trace.runs

    def retime(self, start_ticks: int, start_counter: int) -> None:
        """The same samples on another clock: the first at ``start_ticks``, counter ``start_counter``."""
        shift = start_ticks - self.trace.start_ticks
        self.samples["ticks"] += shift
        self.samples["t"] = self.samples["ticks"] / TICKS_PER_SECOND
        counters = self.samples["counter"].astype(np.int64) + start_counter - self._sensor.start_counter
        self.samples["counter"] = counters & 0xFFFF
        self.trace = dataclasses.replace(self.trace, start_ticks=start_ticks)
        self._sensor.start_counter = start_counter
        self._tail_start = -1  # the still water after it, on the new clock too

    def block(self, start: int, stop: int) -> np.ndarray:
        """Samples ``start`` .. ``stop - 1``."""
        n = self.samples.size
        if stop <= n:
            return self.samples[start:stop]
        head = self.samples[start:n] if start < n else self.samples[:0]
        parts = [head]
        k = max(start, n)
        while k < stop:
            block_start = n + (k - n) // self.tail_block * self.tail_block
            if block_start != self._tail_start:
                trace = still_trace(self.rate_hz, self.scenario.axis, self.trace.start_ticks, block_start,
                                    self.tail_block)  # fmt: skip
                self._tail = self._sensor.measure(trace, block=1 + block_start // self.tail_block)
                self._tail_start = block_start
            upto = min(stop, block_start + self.tail_block)
            parts.append(self._tail[k - block_start : upto - block_start])
            k = upto
        return np.concatenate(parts)


class ScriptedSource:
    """The scenario on the device clock from power-up, at the rate the output is configured to.

    ``then_play`` queues another scenario from a later frame on, on the same clock (a guided session's
    next decay, asked for while the device streams): its frames replace the still water from there.
    """

    plays_from_measurement: bool = False
    configuration: list[tuple[int, int]] | None = None
    identity: DeviceIdentity | None = None

    def __init__(self, scenario: DecayScenario) -> None:
        self.scenario = scenario
        self._by_rate: dict[float, ScenarioSamples] = {}
        self._next: list[tuple[int, ScenarioSamples]] = []  # (first frame, its samples), in frame order
        self._sent = 0  # frames handed out so far: a scenario queued starts after them
        self._lock = threading.Lock()

    def then_play(self, frame: int, samples: ScenarioSamples) -> bool:
        """Play ``samples`` (computed on the caller's thread, not the device's) from ``frame`` on, retimed
        to follow on; False when that frame is already sent (ask again from a later one)."""
        with self._lock:
            if frame < self._sent or (self._next and frame <= self._next[-1][0]):
                return False
            rate_hz = samples.rate_hz
            ticks = int(self.scenario.start_ticks or 0) + round(frame * TICKS_PER_SECOND / rate_hz)
            samples.retime(ticks, (int(self.scenario.start_counter or 0) + frame) & 0xFFFF)
            self._next.append((frame, samples))
        return True

    def samples_at(self, rate_hz: float) -> ScenarioSamples:
        """The scenario played at ``rate_hz`` (the truth in s and ticks is the same at every rate)."""
        if rate_hz not in self._by_rate:
            self._by_rate[rate_hz] = ScenarioSamples(dataclasses.replace(self.scenario, rate_hz=rate_hz))
        return self._by_rate[rate_hz]

    def prepare(self) -> None:
        """Compute the scenario at its own rate now, not in the first sample's turn."""
        self.samples_at(self.scenario.rate_hz)

    @property
    def truth(self) -> list[RunTruth]:
        """The scenario's runs (release instants in s from power-up and in SampleTimeFine ticks)."""
        return self.samples_at(self.scenario.rate_hz).truth

    @property
    def start_ticks(self) -> int:
        return int(self.scenario.start_ticks or 0)

    def rate_hz(self, output: Output) -> float:
        return output.rate_hz

    def due(self, device_s: float, output: Output, *, strict: bool = False) -> int:
        at = device_s * output.rate_hz
        return math.ceil(at) if strict else math.floor(at) + 1

    def time_s(self, index: int, output: Output) -> float:
        return index / output.rate_hz

    def frames(self, start: int, stop: int, output: Output) -> list[bytes]:
        with self._lock:
            self._sent = max(self._sent, stop)
            queued = [(first, samples) for first, samples in self._next if samples.rate_hz == output.rate_hz]
        pieces, k = [], start
        for first, upto, samples in self._pieces(queued, output.rate_hz):
            if k >= stop:
                break
            end = int(min(stop, upto))
            if end > k:
                pieces.append(samples.block(k - first, end - first))
                k = end
        return output.encode(np.concatenate(pieces), np.arange(start, stop))

    def _pieces(
        self, queued: list[tuple[int, ScenarioSamples]], rate_hz: float
    ) -> Iterator[tuple[int, float, ScenarioSamples]]:
        """(first frame, end frame, samples) of what plays: the scenario, then each queued one."""
        first, samples = 0, self.samples_at(rate_hz)
        for start, following in queued:
            yield first, start, samples
            first, samples = start, following
        yield first, math.inf, samples


class RecordedSource:
    """Bytes a device sent, cut after each frame and re-sent at the pace of their SampleTimeFine.

    Every byte goes out as it was recorded, line noise included (bytes between frames travel with
    the frame after them). ``configuration`` is the output configuration the device was in (from
    the recording); without it, it is read off the frames: per-message outputs at 0xFFFF, the
    others at the rate they appear. ``identity``: the device that sent them, when known.
    """

    plays_from_measurement: bool = True

    def __init__(
        self,
        raw: bytes,
        configuration: Sequence[tuple[int, int]] | None = None,
        name: str = "recording",
        identity: DeviceIdentity | None = None,
    ) -> None:
        self.name = name
        self.identity = identity
        buf = np.frombuffer(raw, dtype=np.uint8)
        scan = scan_frames(buf, final=True)
        if not scan.starts.size:
            raise InputError(f"{name} holds no Xsens frames: nothing to play")
        ends = scan.payload_starts + scan.lengths + 1
        cuts = np.concatenate(([0], ends[:-1], [len(raw)]))
        self.segments = [raw[a:b] for a, b in itertools.pairwise(cuts)]
        decoded = decode_buffer(buf, final=True)  # the same frames, as columns (``frame_index`` places them)
        raw_ticks = np.full(scan.starts.size, -1, dtype=np.int64)
        if "SampleTimeFine" in decoded.columns:
            present = decoded.present["SampleTimeFine"]
            raw_ticks[decoded.frame_index[present]] = decoded.columns["SampleTimeFine"][present]
        timed = raw_ticks >= 0
        if not timed.any():
            raise InputError(f"{name}: no frame carries SampleTimeFine, so there is no pace to play them at")
        modulus = MODULUS_32_BIT if raw_ticks.max() >= MODULUS_ONE_DAY else MODULUS_ONE_DAY
        ticks = np.full(raw_ticks.size, np.iinfo(np.int64).min)
        ticks[timed] = SampleTimeUnwrapper(modulus).update_many(raw_ticks[timed])
        first = int(np.argmax(timed))
        ticks[:first] = ticks[first]
        # an untimed frame goes out with the frame before it; so does a GNSS frame, whose time runs late
        ticks = np.maximum.accumulate(ticks)
        self.first_ticks = int(ticks[0])
        self.times_s = (ticks - ticks[0]) / TICKS_PER_SECOND
        steps = np.diff(ticks[timed])
        steps = steps[steps > 0]
        self.nominal_rate_hz = TICKS_PER_SECOND / float(np.median(steps)) if steps.size else 100.0
        self.configuration: list[tuple[int, int]] | None = (
            [(int(x), int(hz)) for x, hz in configuration]
            if configuration
            else _configuration_seen(decoded, ticks[decoded.frame_index])
        )

    def __len__(self) -> int:
        return len(self.segments)

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])

    @property
    def start_ticks(self) -> int:
        return self.first_ticks

    @property
    def truth(self) -> list[RunTruth]:
        return []

    def rate_hz(self, output: Output) -> float:
        return self.nominal_rate_hz

    def due(self, device_s: float, output: Output, *, strict: bool = False) -> int:
        return int(np.searchsorted(self.times_s, device_s, side="left" if strict else "right"))

    def time_s(self, index: int, output: Output) -> float:
        return float(self.times_s[index]) if index < len(self.segments) else math.inf

    def frames(self, start: int, stop: int, output: Output) -> list[bytes]:
        return self.segments[start:stop]


def _configuration_seen(decoded: DecodedBlock, ticks: np.ndarray) -> list[tuple[int, int]]:
    """(xdi, Hz) of the outputs in the MTData2 messages (``ticks``: their device times), in message
    order: per-message outputs at 0xFFFF, the others at the device rate nearest to their usual
    spacing (a real MTi skips a fused output now and then: counting them would understate it)."""
    entries = []
    for name, present in decoded.present.items():
        for xdi in np.unique(decoded.xdis[name][present]).tolist():
            if name in PER_MESSAGE_OUTPUTS:
                entries.append((xdi, MAX_FREQUENCY))
                continue
            steps = np.diff(ticks[present & (decoded.xdis[name] == xdi)])
            steps = steps[steps > 0]
            seen_hz = TICKS_PER_SECOND / float(np.median(steps)) if steps.size else 1.0
            entries.append((xdi, min(DEVICE_RATES_HZ, key=lambda hz: abs(hz - seen_hz))))
    return entries
