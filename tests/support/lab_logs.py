"""Files a lab already has, made for tests: MT Manager ``.mtb`` logs (what the simulated MTi-G sends,
after the Configuration and eMTS messages MT Manager's log starts with) and LabVIEW TDMS files (npTDMS)."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from tankdaq.device.simulator.output import Output, effective_configuration
from tankdaq.physics.scenario import DecayScenario
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.mtb import LogConfiguration, LoggedDevice, configuration_payload
from tankdaq.xsens.mtdata2 import make_xdi

#: A roll decay with known coefficients (1/s and 1/s^2), linear: b1 and c1 are what a fit must find.
TRUE = {"b1": 0.12, "c1": 16.0}
OUTPUTS = ("PacketCounter", "SampleTimeFine", "EulerAngles", "RateOfTurn", "Acceleration", "StatusWord")
DEVICE_ID = 0x077B1A2C


def scenario(seed: int = 3) -> DecayScenario:
    """One scripted roll decay at 100 Hz: still water, a tilt, the release, 30 s of decay."""
    return DecayScenario(
        rate_hz=100, runs=1, seed=seed, release_after_s=12.0, decay_s=30.0, coefficients=TRUE
    )


@functools.cache
def samples_of(seed: int = 3) -> np.ndarray:
    """The scenario's samples (made once per seed: the tests only read them)."""
    samples = scenario(seed).samples()[0]
    samples.flags.writeable = False
    return samples


def mtdata2_frames(samples: np.ndarray, bid: int = 0xFF) -> list[bytes]:
    """What the simulated MTi-G sends for ``samples`` (Euler angles, gyro, acceleration, time, status)."""
    output = Output(items=effective_configuration([(make_xdi(name), 100) for name in OUTPUTS]))
    frames = output.encode(samples, np.arange(samples.size))
    return frames if bid == 0xFF else [bytes((0xFA, bid)) + rebuilt(f, bid)[2:] for f in frames]


def rebuilt(frame: bytes, bid: int) -> bytes:
    """The same message with another bus id (its checksum made again)."""
    return build_frame(frame[2], frame[4:-1], bid)


def extended(frame: bytes) -> bytes:
    """A standard frame in the extended-length form (``FA BID MID FF LENH LENL DATA CS``), as logs hold."""
    bid, mid, payload = frame[1], frame[2], frame[4:-1]
    body = bytes((bid, mid, 0xFF, len(payload) >> 8, len(payload) & 0xFF)) + payload
    return b"\xfa" + body + bytes(((-sum(body)) & 0xFF,))


def configuration(devices: int = 1) -> LogConfiguration:
    """A Configuration message's content: one MTi-G, or an Awinda station's ``devices`` MTw sensors."""
    found = tuple(LoggedDevice(k + 1, DEVICE_ID + k, 2, "1.8.2") for k in range(devices))
    return LogConfiguration(DEVICE_ID if devices == 1 else 0x02801234, 0, "20241105", "14302100", "", found)


def header_frames(devices: int = 1) -> list[bytes]:
    """What an MT Manager log starts with: Configuration, then eMTS (1320 bytes: extended length)."""
    emts = bytes(range(256)) * 5 + bytes(40)
    return [build_frame(MID.CONFIGURATION, configuration_payload(configuration(devices))),
            build_frame(0x91, emts)]  # fmt: skip


def single_device_log(path: Path, seed: int = 3) -> tuple[Path, int]:
    """An MTi-G's log: header, MTData2 (every 7th in extended form), an unknown 0x98 now and then;
    returns the path and the number of MTData2 frames."""
    frames = mtdata2_frames(samples_of(seed))
    body = []
    for k, frame in enumerate(frames):
        body.append(extended(frame) if k % 7 == 3 else frame)
        if k % 500 == 250:
            body.append(build_frame(0x98, bytes(12)))
    path.write_bytes(b"".join(header_frames() + body))
    return path, len(frames)


def bus_log(path: Path, devices: int = 3, seed: int = 3) -> tuple[Path, int]:
    """An Awinda station's log by hand: bus ids 1..``devices`` interleaved, each device's decay its own
    (seeds differ), a MasterSettings-like 0x8B and 0x98 between them; returns the path and the number of
    MTData2 frames per device."""
    per_device = [mtdata2_frames(samples_of(seed + k), bid=k + 1) for k in range(devices)]
    count = min(len(frames) for frames in per_device)
    body = [build_frame(0x8B, bytes(8))]
    for k in range(count):
        body += [frames[k] for frames in per_device]
        if k % 400 == 0:
            body.append(build_frame(0x98, bytes(6), bid=1))
    path.write_bytes(b"".join(header_frames(devices) + body))
    return path, count


def tdms_file(path: Path, t: np.ndarray, roll: np.ndarray, speed_m_s: np.ndarray, unit: str = "deg") -> Path:
    """A LabVIEW-like TDMS file: group ``Carriage`` with a waveform roll channel (in ``unit``) and a speed
    channel (m/s), as npTDMS writes them."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    wave = {"wf_start_time": np.datetime64("2024-11-05T14:30:21"), "wf_start_offset": 0.0,
            "wf_increment": float(t[1] - t[0]), "wf_samples": t.size}  # fmt: skip
    with TdmsWriter(str(path)) as writer:
        writer.write_segment([
            RootObject({"name": "tow 12", "operator": "lab"}),
            GroupObject("Carriage"),
            ChannelObject("Carriage", "Roll", roll, {**wave, "unit_string": unit}),
            ChannelObject("Carriage", "Speed", speed_m_s, {**wave, "unit_string": "m/s"}),
        ])  # fmt: skip
    return path
