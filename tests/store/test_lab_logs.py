"""MT Manager ``.mtb`` logs and LabVIEW TDMS files as decay inputs: every frame of every device decoded,
none counted as corruption, the header kept, the same fit as a plain CSV of the same decay."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import tankdaq
from support.lab_logs import DEVICE_ID, TRUE, bus_log, samples_of, single_device_log, tdms_file
from tankdaq.api.identification import Reading
from tankdaq.cli import app
from tankdaq.errors import BadIdentificationInput, InputError
from tankdaq.store.csv_import import CsvOptions
from tankdaq.store.mtb_file import read_mtb
from tankdaq.xsens.column_decoder import decode_capture
from tankdaq.xsens.framer import ANY_BID, StreamFramer
from tankdaq.xsens.mtb import LOG_MAX_DATA_LENGTH, decode_log
from tankdaq.xsens.stream_decoder import StreamDecoder

runner = CliRunner()


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, int]]:
    folder = tmp_path_factory.mktemp("logs")
    return {"one": single_device_log(folder / "one.mtb"), "bus": bus_log(folder / "bus.mtb", devices=3)}


@pytest.mark.slow  # the module's logs: three simulated decays, encoded frame by frame
def test_a_simulated_mti_g_log_decodes_every_mtdata2_frame_and_keeps_its_configuration(
    logs: dict[str, tuple[Path, int]],
) -> None:
    """Configuration, eMTS (extended length), MTData2 (every 7th in extended form) and an unknown 0x98:
    every MTData2 frame is a message, the others are counted by id, nothing is corruption."""
    path, frames = logs["one"]
    log = decode_log(path.read_bytes())
    assert log.whole.n_messages == frames
    assert (log.whole.bad_checksums, log.whole.skipped_bytes, log.whole.false_syncs) == (0, 0, 0)
    unknown = len(range(250, frames, 500))  # the helper puts a 0x98 after every 500th frame from the 250th
    assert dict(log.not_read) == {0x91: 1, 0x98: unknown}
    assert log.configuration is not None
    meta = log.configuration.metadata(0xFF)
    assert meta["device_id"] == f"{DEVICE_ID:08X}"
    assert (meta["firmware"], meta["filter_profile"]) == ("1.8.2", 2)
    assert (meta["log_date"], meta["log_time"], meta["log_sampling_period"]) == ("20241105", "14302100", 0)
    said = f"skipped {unknown + 1} messages not read (eMTS 0x91 x1, 0x98 x{unknown}); 0 bad checksums"
    assert said in log.summary()


@pytest.mark.slow
def test_several_bus_ids_are_one_stream_per_device_and_none_is_corrupt(
    logs: dict[str, tuple[Path, int]],
) -> None:
    """An Awinda-like log (bus ids 1-3 interleaved): each device's every frame, in the batch and in
    the streaming decoder fed in small pieces and the reference framer alike; the live decoder (master
    bus ids only) calls most of it corrupt, as the issue reported."""
    path, frames = logs["bus"]
    data = path.read_bytes()
    log = decode_log(data)
    assert {bus: block.n_messages for bus, block in log.devices.items()} == {1: frames, 2: frames, 3: frames}
    assert (log.whole.bad_checksums, log.whole.skipped_bytes, log.whole.false_syncs) == (0, 0, 0)
    assert {bus: int(block.columns["PacketCounter"][0]) for bus, block in log.devices.items()} == {
        1: 3,
        2: 4,
        3: 5,
    }
    decoder = StreamDecoder(LOG_MAX_DATA_LENGTH, ANY_BID)
    for start in range(0, len(data), 4093):
        decoder.feed(data[start : start + 4093])
    decoder.finish()
    framer = StreamFramer(LOG_MAX_DATA_LENGTH, ANY_BID)
    assert len(framer.feed(data) + framer.finish()) == log.whole.frames
    assert (decoder.messages, decoder.skipped_bytes, framer.skipped_bytes) == (3 * frames, 0, 0)
    live = decode_capture(data)
    assert live.n_messages < frames + 1 and live.false_syncs > frames


@pytest.mark.slow
def test_an_mtb_log_is_identified_within_one_percent_of_the_truth(logs: dict[str, tuple[Path, int]]) -> None:
    """identify reads the log (time from SampleTimeFine, the Configuration's sampling period being 0)."""
    path, _ = logs["one"]
    fit = tankdaq.identify(path, "b1,c1").fits[0]
    for term, truth in TRUE.items():
        assert fit.estimator.coefficients_[term] == pytest.approx(truth, rel=0.01)
    assert fit.runs[0].meta["device_id"] == f"{DEVICE_ID:08X}"
    assert fit.runs[0].meta["sample_rate_hz"] == pytest.approx(100.0)


@pytest.mark.slow
def test_a_device_of_several_is_chosen_by_id_or_bus_id(logs: dict[str, tuple[Path, int]]) -> None:
    path, _ = logs["bus"]
    with pytest.raises(InputError, match=r"holds 3 devices .*077B1A2C, 077B1A2D, 077B1A2E.*device="):
        tankdaq.read(path)
    assert tankdaq.read(path, device="077b1a2d").meta["device_id"] == "077B1A2D"
    assert tankdaq.read(path, device="3").meta["device_id"] == "077B1A2E"
    with pytest.raises(InputError, match=r"no device '9'.*077B1A2C \(bus 1\)"):
        tankdaq.read(path, device="9")
    runs = tankdaq.identify(path, "b1,c1", reading=Reading(device="2")).fits[0].runs
    assert [run.meta["bus_id"] for run in runs] == [2]


@pytest.mark.slow
def test_decode_reports_a_log_per_device(logs: dict[str, tuple[Path, int]], tmp_path: Path) -> None:
    path, frames = logs["bus"]
    result = runner.invoke(app, ["decode", str(path), "--out", str(tmp_path / "out.jsonl")])
    assert result.exit_code == 0, result.output
    assert (
        f"077B1A2C (bus 1): {frames}, 077B1A2D (bus 2): {frames}, 077B1A2E (bus 3): {frames}" in result.output
    )
    assert "0x8B x1" in result.output and "0 bad checksums, 0 skipped bytes" in result.output
    import json

    rows = [json.loads(line) for line in (tmp_path / "out.jsonl").read_text().splitlines()]
    assert len(rows) == 3 * frames
    assert [row["BusId"] for row in rows[:6]] == [1, 2, 3, 1, 2, 3]  # which device sent each


@pytest.mark.slow
def test_export_of_a_log_writes_each_device_decay_with_its_device(
    logs: dict[str, tuple[Path, int]], tmp_path: Path
) -> None:
    """``export`` of a log: its decays become recordings (as import makes them), then CSV files whose
    sidecars say the device and the source."""
    import json

    result = runner.invoke(app, ["export", str(logs["bus"][0]), "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    sidecars = sorted(tmp_path.glob("bus-*.json"))
    assert len(sidecars) == 3 and len(list(tmp_path.glob("bus-*.csv"))) == 3
    meta = [json.loads(path.read_text()) for path in sidecars]
    assert sorted(m["device_id"] for m in meta) == ["077B1A2C", "077B1A2D", "077B1A2E"]
    assert {m["source_format"] for m in meta} == {"MT Manager log"}


# ---- LabVIEW TDMS ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tow(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One decay as a TDMS file (roll in deg, a speed channel of 1.2 m/s) and as a plain CSV."""
    folder = tmp_path_factory.mktemp("tdms")
    samples = samples_of(4)
    t, roll = samples["t"] - samples["t"][0], np.degrees(samples["roll"])
    speed = np.full(t.size, 1.2) + 0.002 * np.sin(3 * t)
    csv = folder / "tow.csv"
    csv.write_text(
        "time_s,angle_deg\n"
        + "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), roll.tolist(), strict=True))
    )
    return {"tdms": tdms_file(folder / "tow.tdms", t, roll, speed), "csv": csv}


@pytest.mark.slow
def test_a_tdms_file_gives_the_csv_fit_and_the_speed(tow: dict[str, Path]) -> None:
    reading = Reading(angle_col="Carriage/Roll", speed_col="Carriage/Speed")
    from_tdms = tankdaq.identify(tow["tdms"], "b1,c1", reading=reading).fits[0]
    from_csv = tankdaq.identify(tow["csv"], "b1,c1").fits[0]
    for term in TRUE:
        assert from_tdms.estimator.coefficients_[term] == pytest.approx(
            from_csv.estimator.coefficients_[term], rel=1e-9
        )
    assert from_tdms.runs[0].meta["speed_m_s"] == pytest.approx(1.2, abs=0.002)
    assert from_tdms.runs[0].meta["tdms_name"] == "tow 12"
    assert "speed_m_s" not in from_csv.runs[0].meta


def test_tdms_channels_are_found_by_name_and_units_by_unit_string(
    tow: dict[str, Path], tmp_path: Path
) -> None:
    """Without --angle-col the channel named Roll is the angle; a channel in rad says so in unit_string."""
    recording = tankdaq.read(tow["tdms"])
    assert recording.meta["speed_m_s"] == pytest.approx(1.2, abs=0.002)
    assert any("channel Carriage/Roll read as the roll" in line for line in recording.notices)
    t = np.arange(3000) * 0.01
    roll = np.radians(8.0) * np.exp(-0.06 * t) * np.cos(4.0 * t)  # 8 deg, in rad: its unit_string says so
    (decay,) = tankdaq.read(tdms_file(tmp_path / "rad.tdms", t, roll, np.zeros(t.size), unit="rad")).decays
    assert decay.initial_angle_deg == pytest.approx(8.0, abs=0.05)


def test_a_missing_tdms_channel_is_one_line(tow: dict[str, Path]) -> None:
    with pytest.raises(InputError, match="no speed column 'Carriage/Sped'"):
        tankdaq.read(tow["tdms"], angle_col="Carriage/Roll", speed_col="Carriage/Sped")
    # a channel named and absent is refused, never replaced by the Roll found by its name
    with pytest.raises(InputError, match="no channel 'Carriage/Rol'"):
        tankdaq.read(tow["tdms"], angle_col="Carriage/Rol")


@pytest.mark.slow
def test_catalogue_index_adds_a_log_with_its_device(
    logs: dict[str, tuple[Path, int]], tmp_path: Path
) -> None:
    """``catalogue index`` reads .mtb logs as decay files: one row each, its device from the Configuration."""
    catalogue = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    result = runner.invoke(app, ["catalogue", "index", str(logs["one"][0].parent), "--catalogue", catalogue])
    assert result.exit_code == 0, result.output
    assert "2 added" in result.output and "0 skipped" in result.output
    rows = tankdaq.runs(catalogue=catalogue)
    assert sorted(Path(p).name for p in rows["path"]) == ["bus.mtb", "one.mtb"]
    assert set(rows["device_id"]) == {f"{DEVICE_ID:08X}"} and set(rows["firmware"]) == {"1.8.2"}


@pytest.mark.parametrize(
    ("frame", "name"), [("NED", "EulerAngles"), ("NWU", "Quaternion"), ("NED", "RotationMatrix")]
)
@pytest.mark.slow
def test_orientation_logged_in_ned_or_nwu_is_read_as_enu(frame: str, name: str, tmp_path: Path) -> None:
    """A log whose orientation is in another earth frame (its local frame turned, as RotLocal turns it):
    the same roll and pitch as in ENU, said in a line, never dropped as a foreign frame."""
    from tankdaq.xsens.constants import MID
    from tankdaq.xsens.frame import build_frame
    from tankdaq.xsens.mtdata2 import encode_mtdata2, make_xdi
    from tankdaq.xsens.orientation import euler_from_matrix, quaternion, rotation_matrix

    samples = samples_of(3)[::4]
    turn = {"NED": [[0, 1, 0], [1, 0, 0], [0, 0, -1]], "NWU": [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]}[frame]
    wire = (
        rotation_matrix(samples["roll"], samples["pitch"], samples["yaw"])
        .reshape(-1, 3, 3)
        .transpose(0, 2, 1)
    )
    logged = euler_from_matrix((np.array(turn, float) @ wire).transpose(0, 2, 1).reshape(-1, 9))
    forms = {"EulerAngles": lambda e: tuple(np.degrees(e)), "Quaternion": lambda e: tuple(quaternion(*e)),
             "RotationMatrix": lambda e: tuple(rotation_matrix(*e))}  # fmt: skip
    time_xdi, orientation_xdi = make_xdi("SampleTimeFine"), make_xdi(name, "float64", frame)
    path = tmp_path / "framed.mtb"
    path.write_bytes(
        b"".join(
            build_frame(
                MID.MTDATA2, encode_mtdata2([(time_xdi, int(s["ticks"])), (orientation_xdi, forms[name](e))])
            )
            for s, e in zip(samples, logged, strict=True)
        )
    )
    (run,) = read_mtb(path, None, CsvOptions(keep_all=True))
    assert run.angle == pytest.approx(samples["roll"], abs=1e-9)
    assert run.channels["other_angle_pitch"] == pytest.approx(samples["pitch"], abs=1e-9)
    assert f"turned to ENU ({samples.size} in {frame})" in run.meta["notices"][1]


@pytest.mark.slow
def test_a_device_without_orientation_is_named_and_the_others_read(tmp_path: Path) -> None:
    """A station's own MTData2 (no orientation, no time) beside a sensor's: the sensor is read, the
    station named in a line with what it sent; a log of nothing usable is one line."""
    from support.lab_logs import header_frames, mtdata2_frames
    from tankdaq.xsens.constants import MID
    from tankdaq.xsens.frame import build_frame
    from tankdaq.xsens.mtdata2 import encode_mtdata2, make_xdi

    station = build_frame(MID.MTDATA2, encode_mtdata2([(make_xdi("PacketCounter"), 7)]))
    sensor = mtdata2_frames(samples_of(3), bid=1)
    path = tmp_path / "station.mtb"
    path.write_bytes(b"".join([*header_frames(1), *(f + station for f in sensor)]))
    (run,) = read_mtb(path, None, CsvOptions())
    assert run.meta["bus_id"] == 1 and run.t.size == len(sensor)
    assert any("not read: " in line and "(master): 0 samples" in line and "PacketCounter" in line
               for line in run.meta["notices"])  # fmt: skip
    only = tmp_path / "only.mtb"
    only.write_bytes(station * 50)
    with pytest.raises(BadIdentificationInput, match=r"it sent PacketCounter\); a decay needs at least"):
        read_mtb(only, None, CsvOptions())
