"""A recorded device played again through the simulator's pty into the real driver.

A decay recorded from the scripted simulator is played back (``--port sim:FILE.mcap``) and
recorded again: same samples (angles, device time), release at the same sample. Real bytes no
one here wrote (einride's MTi captures) go through the same path and decode to their reference.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from support.record_settings import sim_record_settings
from support.xsens_captures import capture_dir, read_golden_blocks
from tankdaq.acquire.daemon import RecordDaemon
from tankdaq.cli import app
from tankdaq.device.decoding import SampleDecoder
from tankdaq.device.driver import MTiDriver
from tankdaq.device.factory import SimPort
from tankdaq.device.simulator import DeviceIdentity, RecordedSource, SimulatedMTi
from tankdaq.device.simulator.playback import recorded_device
from tankdaq.errors import InputError
from tankdaq.records import DecayEnd
from tankdaq.store.reader import StoredRecording, read_recording
from tankdaq.xsens.control import parse_output_configuration

#: Device clock speed-up of the recordings (as the other record tests).
SPEED = 6.0
#: Both recordings keep their whole history before the release: the replay then holds the still
#: water the first detector learnt its rest angle from.
PRETRIGGER_S = 30.0
#: Columns that come from the device (host arrival time is the only one that differs).
DEVICE_COLUMNS = ("t", "ticks", "counter", "roll", "pitch", "yaw", "p", "q", "r", "ax", "ay", "az", "status")


def _record(port: str, out: Path) -> StoredRecording:
    settings = sim_record_settings(
        out, port=port, runs=1, sim_speed=SPEED, sim_seed=3, pretrigger_s=PRETRIGGER_S
    )
    (outcome,) = RecordDaemon(settings).run()
    assert outcome.ended is DecayEnd.SETTLED  # settled as a decay does: not cut short by the end of a tape
    return read_recording(outcome.path)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[StoredRecording, StoredRecording]:
    """A decay from the scripted simulator, and the same decay recorded again from its played-back device."""
    base = tmp_path_factory.mktemp("playback")
    first = _record("sim", base / "first")
    again = _record(f"sim:{first.path}", base / "again")
    return first, again


@pytest.mark.slow
def test_a_played_back_recording_records_the_same_samples(
    recorded: tuple[StoredRecording, StoredRecording],
) -> None:
    first, again = recorded
    a, b = first.samples, again.samples
    offset = int(np.searchsorted(a["ticks"], b["ticks"][0]))
    assert a["ticks"][offset] == b["ticks"][0]
    n = min(a.size - offset, b.size)
    for column in DEVICE_COLUMNS:
        np.testing.assert_array_equal(b[column][:n], a[column][offset : offset + n], err_msg=column)
    # the overlap covers the whole decay: from the very first frame (the frames that came with
    # GoToMeasurement's ack are the stream's start) to the settle. The settle is seen at the end of a
    # block (one read, its samples one host arrival time), and a read brings more samples the later it
    # comes, so each recording ends somewhere in the block where the other one settled, never before it
    assert offset == 0
    assert n >= _last_block_start(a) and n >= _last_block_start(b), (n, a.size, b.size)
    assert first.release_index is not None and again.release_index is not None
    assert b["ticks"][again.release_index] == a["ticks"][first.release_index]
    (release_a,) = [e for e in first.events if e["kind"] == "release"]
    (release_b,) = [e for e in again.events if e["kind"] == "release"]
    assert release_b["data"]["first_free_sample_t_s"] == release_a["data"]["first_free_sample_t_s"]
    assert release_b["t_s"] == release_a["t_s"]
    assert release_b["data"]["release_se_s"] == release_a["data"]["release_se_s"] > 0


@pytest.mark.slow
def test_the_played_back_device_is_the_recorded_one(
    recorded: tuple[StoredRecording, StoredRecording],
) -> None:
    first, again = recorded
    assert again.metadata["port"].endswith("ttyMTi0") and again.metadata["product_code"] == "MTi-G-710-2A8G4"
    for setting in ("configuration", "device_id", "product_code", "firmware"):
        assert again.run_config["device"][setting] == first.run_config["device"][setting], setting
    assert recorded_device(first.path).identity == DeviceIdentity.mti_g_710()  # the scripted device's
    assert again.metadata["link_gaps"] == "0" and again.metadata["link_lost"] == "0"


@pytest.mark.slow
def test_a_recording_source_keeps_every_byte_and_reads_its_configuration_off_the_frames(
    recorded: tuple[StoredRecording, StoredRecording],
) -> None:
    first, _ = recorded
    raw = b"".join(chunk for _, chunk in first.raw_chunks)
    source = recorded_device(first.path)
    assert b"".join(source.segments) == raw
    assert source.nominal_rate_hz == 100.0
    assert source.configuration == [tuple(e) for e in first.run_config["device"]["configuration"]]
    assert RecordedSource(raw).configuration == source.configuration  # read off the frames: the same
    decoded, _ = SampleDecoder().feed(raw, 0.0)
    assert np.allclose(source.times_s[: decoded.size], (decoded["ticks"] - decoded["ticks"][0]) / 10_000)


# ---- real bytes: einride's MTi captures ----------------------------------------


def _golden_by_counter(name: str) -> dict[int, dict[str, list[str]]]:
    blocks = read_golden_blocks(capture_dir(name) / "output.golden")
    by_counter = {}
    for block in blocks:
        fields = {field[0]: field[3] for field in block}
        if "PacketCounter" in fields:
            by_counter[int(fields["PacketCounter"][0])] = fields
    return by_counter


def _values(lines: list[str]) -> np.ndarray:
    return np.array([float(line.split(":")[-1]) for line in lines], dtype=np.float32)


@pytest.mark.slow
def test_a_real_capture_plays_through_the_driver_to_its_reference_decode() -> None:
    path = capture_dir("einride-1")
    configuration = parse_output_configuration((path / "outputconfig.bin").read_bytes())
    source = RecordedSource((path / "output.bin").read_bytes(), configuration, name="einride-1")
    golden = _golden_by_counter("einride-1")
    inertial = {counter: fields for counter, fields in golden.items() if "Acceleration" in fields}
    last = max(inertial)
    samples = [np.zeros(0)]
    with SimulatedMTi(source=source, speed=2.0) as sim, MTiDriver(sim.link, rate_hz=100) as driver:
        driver.configure()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not (samples[-1].size and samples[-1]["counter"][-1] == last):
            samples.append(driver.read_block().samples)
    got = np.concatenate(samples[1:])
    assert got["counter"][-1] == last
    assert got.size == len(inertial), (got.size, len(inertial))  # every frame, the first ones too
    for sample in got:
        fields = inertial[int(sample["counter"])]
        assert int(sample["ticks"]) == int(fields["SampleTimeFine"][0])
        assert int(sample["status"]) == int(fields["StatusWord"][0], 2)
        for name, columns in {"Acceleration": ("ax", "ay", "az"), "RateOfTurn": ("p", "q", "r")}.items():
            np.testing.assert_array_equal(np.float32([sample[c] for c in columns]), _values(fields[name]))
        if "EulerAngles" in fields:
            euler = np.float32([math.degrees(sample[c]) for c in ("roll", "pitch", "yaw")])
            np.testing.assert_array_equal(euler, _values(fields["EulerAngles"]))


#: Set 5's device was configured for BaroPressure at 100 Hz but sent it in every other message: read
#: off the frames it is 50 Hz, what the device really did, so that set cannot match its configuration.
@pytest.mark.parametrize("name", [f"einride-{n}" for n in range(1, 5)])
def test_the_configuration_read_off_real_frames_is_the_one_the_device_reported(name: str) -> None:
    path = capture_dir(name)
    reported = parse_output_configuration((path / "outputconfig.bin").read_bytes())
    source = RecordedSource((path / "output.bin").read_bytes(), name=name)
    assert source.configuration is not None and sorted(source.configuration) == sorted(reported)
    assert source.nominal_rate_hz == 100.0


# ---- the command line ----------------------------------------


def test_the_sim_port_names_a_recording() -> None:
    assert SimPort.parse("sim") == SimPort()
    assert SimPort.parse("sim:run.mcap") == SimPort(Path("run.mcap"))
    assert SimPort.parse("/dev/ttyUSB0") is None and SimPort.parse("simulator") is None
    with pytest.raises(InputError):
        SimPort.parse("sim:")


@pytest.mark.parametrize(
    ("target", "mentions"),
    [
        ("missing", "no such recording"),
        ("not-mcap", "is not an MCAP file"),
        ("rate", "recorded at 100 Hz: give --rate 100"),
    ],
)
@pytest.mark.slow
def test_a_bad_recording_is_refused_before_the_device_opens(
    recorded: tuple[StoredRecording, StoredRecording],
    tmp_path: Path,
    private_tempdir: Path,
    target: str,
    mentions: str,
) -> None:
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("not a recording")
    files = {"missing": tmp_path / "missing.mcap", "not-mcap": not_mcap, "rate": recorded[0].path}
    rate = "200" if target == "rate" else "100"
    args = ["record", "--port", f"sim:{files[target]}", "--hull", "swath", "--draft", "T", "--angle", "8",
            "--viewer", "none", "--runs", "1", "--rate", rate, "--out", str(tmp_path / "out")]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and mentions in lines[0], result.stderr
    assert not list(private_tempdir.iterdir()) and not (tmp_path / "out").exists()


@pytest.mark.slow
def test_simulate_replay_serves_the_recorded_device(
    recorded: tuple[StoredRecording, StoredRecording],
) -> None:
    first, _ = recorded
    tankdaq = str(Path(sys.executable).with_name("tankdaq"))
    process = subprocess.Popen([tankdaq, "simulate", "--replay", str(first.path), "--speed", str(SPEED)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        link = process.stdout.readline().strip()  # type: ignore[union-attr]
        assert link, process.stderr.read()  # type: ignore[union-attr]
        with MTiDriver(link, rate_hz=100) as driver:
            got = driver.samples(2.0)
    finally:
        process.terminate()
        _, err = process.communicate(timeout=30)
    assert process.returncode == 0 and "playing the device of" in err
    raw = b"".join(chunk for _, chunk in first.raw_chunks)
    a, _ = SampleDecoder().feed(raw, 0.0)  # decoded as the driver decodes
    offset = int(np.searchsorted(a["ticks"], got["ticks"][0]))
    assert offset == 0 and got.size >= 150, offset  # from the recording's first frame
    for column in DEVICE_COLUMNS:
        np.testing.assert_array_equal(got[column], a[column][offset : offset + got.size], err_msg=column)


def _last_block_start(samples: np.ndarray) -> int:
    """The index of the first sample of the recording's last read (they share its host arrival time)."""
    return int(np.flatnonzero(samples["host_t"] != samples["host_t"][-1])[-1]) + 1
