"""Write files of the kinds a lab already has into a folder, to try what docs/lab-files.md shows.

``python examples/make_lab_files.py examples/lab``: in that folder (made; a file already there is kept)

- ``MT_example.txt``: an Xsens MT Manager 2022.2 text export (its ``//`` block, tab-separated,
  PacketCounter, SampleTimeFine, the orientation as a quaternion) of a roll decay at 100 Hz;
- ``awinda.mtb``: an MT Manager log of an Awinda station with two MTw sensors (bus ids 1 and 2), each
  with its own roll decay: the Configuration message, then MTData2 as the simulated MTi-G sends it;
- ``tow.tdms``: a LabVIEW TDMS file of a carriage (group ``Carriage``, channels ``Roll`` in degrees and
  ``Speed`` in m/s), one decay at 0.8 m/s.

Every decay is made by tankdaq's own simulator from known coefficients, never copied from a lab's data.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tankdaq.device.simulator.output import Output, effective_configuration
from tankdaq.physics.scenario import DecayScenario
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.mtb import LogConfiguration, LoggedDevice, configuration_payload
from tankdaq.xsens.mtdata2 import make_xdi
from tankdaq.xsens.orientation import quaternion

#: The roll decay's coefficients (1/s, 1/s^2): what identify finds in each file.
TRUE = {"b1": 0.12, "c1": 16.0}
RATE_HZ = 100
OUTPUTS = ("PacketCounter", "SampleTimeFine", "EulerAngles", "RateOfTurn", "Acceleration", "StatusWord")
FIRST_DEVICE = 0x077B1A2C


def samples(seed: int, decay_s: float = 20.0) -> np.ndarray:
    """One simulated roll decay at 100 Hz: still water, the tilt, the release, ``decay_s`` of decay."""
    scenario = DecayScenario(
        rate_hz=RATE_HZ, runs=1, seed=seed, release_after_s=4.0, decay_s=decay_s, coefficients=TRUE
    )
    return scenario.samples()[0]


def mt_manager_export(path: Path) -> None:
    """The decay as MT Manager 2022.2 exports it: its header block, tab-separated, quaternion columns."""
    decay = samples(seed=5)
    q = quaternion(decay["roll"], decay["pitch"], decay["yaw"])  # rad
    header = [
        "// General information: ",
        "//  MT Manager version: 2022.2.0 ",
        "// Device information: ",
        "//  DeviceId: 00B4227B",
        "//  ProductCode: MTi-G-710-2A8G4",
        "//  Firmware Version: 1.8.2",
        "// Device settings: ",
        "//  Filter Profile: General(11.1)",
        "// Coordinate system: ENU",
        "",
        "\t".join(["PacketCounter", "SampleTimeFine", "Quat_q0", "Quat_q1", "Quat_q2", "Quat_q3"]),
    ]
    ticks, counter = decay["ticks"], decay["counter"]
    rows = [
        "\t".join([f"{counter[k]:05d}", str(ticks[k]), *(f"{v:.6f}" for v in q[k])])
        for k in range(q.shape[0])
    ]
    path.write_text("\r\n".join([*header, *rows]) + "\r\n", encoding="utf-8", newline="")


def awinda_log(path: Path, devices: int = 2) -> None:
    """An Awinda station's log: the Configuration message, then each MTw's MTData2 frames interleaved."""
    output = Output(items=effective_configuration([(make_xdi(name), RATE_HZ) for name in OUTPUTS]))
    per_device = []
    for k in range(devices):
        decay = samples(seed=3 + k)
        frames = output.encode(decay, np.arange(decay.size))
        per_device.append([build_frame(f[2], f[4:-1], k + 1) for f in frames])  # bus id k + 1
    found = tuple(LoggedDevice(k + 1, FIRST_DEVICE + k, 2, "4.6.0") for k in range(devices))
    config = LogConfiguration(0x02801234, 0, "20241105", "14302100", "", found)
    body = [build_frame(MID.CONFIGURATION, configuration_payload(config))]
    for k in range(min(len(frames) for frames in per_device)):
        body += [frames[k] for frames in per_device]
    path.write_bytes(b"".join(body))


def carriage_tdms(path: Path) -> None:
    """A carriage's TDMS file: the roll (deg) and the carriage speed (m/s) as waveform channels."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    decay = samples(seed=3)
    roll_deg = np.degrees(decay["roll"])
    speed = np.full(roll_deg.size, 0.8)
    wave = {"wf_start_time": np.datetime64("2024-11-05T14:30:21"), "wf_start_offset": 0.0,
            "wf_increment": 1.0 / RATE_HZ, "wf_samples": roll_deg.size}  # fmt: skip
    with TdmsWriter(str(path)) as writer:
        writer.write_segment([
            RootObject({"name": "tow 12"}),
            GroupObject("Carriage"),
            ChannelObject("Carriage", "Roll", roll_deg, {**wave, "unit_string": "deg"}),
            ChannelObject("Carriage", "Speed", speed, {**wave, "unit_string": "m/s"}),
        ])  # fmt: skip


def main(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    writers = {"MT_example.txt": mt_manager_export, "awinda.mtb": awinda_log, "tow.tdms": carriage_tdms}
    for name, write in writers.items():
        path = folder / name
        if path.exists():  # never over a file (a user's, or this script's from before)
            print(f"kept {path} (it exists)")
            continue
        write(path)
        print(f"wrote {path}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python examples/make_lab_files.py FOLDER")
    main(Path(sys.argv[1]))
