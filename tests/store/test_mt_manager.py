"""Xsens MT Manager text exports (issue 41, items 1 and 2): every generation's header, every delimiter,
Euler, quaternion or matrix columns, SampleTimeFine wrapping at one day or 2**32, or only PacketCounter
and a rate; the same fit as the plain CSV of the same decay, the choices said in one line, the header's
facts kept as metadata, and an orientation component given as the angle refused. The files are written
here from a decay of known coefficients (``mt_manager_files``); the real CLI reads them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa
from typer.testing import CliRunner

import tankdaq
from store.test_csv_untrusted import one_error_line, write_csv
from support.held_tilt import TRUTH, held_tilt
from support.mt_manager_files import orientation, write_export
from tankdaq.catalogue.database import open_catalogue
from tankdaq.catalogue.index import index_folder
from tankdaq.catalogue.schema import decays
from tankdaq.cli import app
from tankdaq.store.orientation_columns import matrix_index
from tankdaq.xsens.orientation import euler_from_matrix, euler_from_quaternion

runner = CliRunner()
MODEL = ("--model", "ittc-quadratic")


def identify(*args: object):
    return runner.invoke(app, ["identify", *map(str, args)])


def fitted(result) -> dict[str, float]:
    assert result.exit_code == 0, result.output
    return {k: v["value"] for k, v in json.loads(result.stdout)["coefficients"].items()}


@pytest.fixture(scope="module")
def plain_fit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, float]:
    """The same decay as a plain CSV (time_s, angle_deg): the fit every export must give."""
    t, angle, _ = held_tilt()
    folder = tmp_path_factory.mktemp("plain")
    path = write_csv(folder / "plain.csv", {"time_s": t, "angle_deg": np.degrees(angle)})
    return fitted(identify(path, *MODEL, "--json"))


#: (file name, write_export settings, extra arguments, the time line expected)
CASES = [
    (
        "v4_roll.txt",
        {"generation": "4.x"},
        (),
        "time from SampleTimeFine (10 kHz ticks, unwrapped at one day",
    ),
    (
        "v4_matrix_counter.txt",
        {"generation": "4.x", "kind": "Mat", "sample_time": False},
        (),
        "time from PacketCounter at the header's Update Rate 100 Hz (no SampleTimeFine values; counter "
        "wrapped at 2^16 1 time, 0 packets missing)",
    ),
    (
        "v2019_euler.csv",
        {"generation": "2019.2", "kind": "Euler", "delimiter": ",", "missing": "NaN", "crlf": False},
        (),
        "unwrapped at one day (864e6 ticks): 0 wraps",
    ),
    (
        "v2019_quat_day_wrap.txt",
        {"generation": "2019.2", "kind": "Quat", "delimiter": ";", "start_tick": 864_000_000 - 20_000},
        (),
        "unwrapped at one day (864e6 ticks): 1 wrap",
    ),
    (
        "v2022_quat_32bit_wrap.txt",
        {"generation": "2022.2", "kind": "Quat", "start_tick": 2**32 - 30_000, "modulus": 2**32},
        (),
        "time from SampleTimeFine (10 kHz ticks, unwrapped at 2^32: 1 wrap)",
    ),
    (
        "v2022_space.txt",
        {"generation": "2022.2", "delimiter": " ", "missing": "NaN"},
        (),
        "unwrapped at 2^32",
    ),
    (
        "v2022_matrix_rate.csv",
        {"generation": "2022.2", "kind": "Mat", "delimiter": ",", "sample_time": False, "missing": "NaN"},
        ("--rate", "100"),
        "time from PacketCounter at --rate 100 Hz",
    ),
]


@pytest.mark.parametrize(("name", "settings", "extra", "time_line"), CASES, ids=[c[0] for c in CASES])
@pytest.mark.slow
def test_every_mt_manager_style_gives_the_plain_csvs_fit(
    tmp_path: Path, plain_fit: dict[str, float], name: str, settings: dict, extra: tuple, time_line: str
) -> None:
    path = write_export(tmp_path / name, **settings)
    result = identify(path, *MODEL, *extra, "--json")
    found = fitted(result)
    for term in ("b1", "c1"):
        assert found[term] == pytest.approx(TRUTH[term], rel=0.01), term
        assert found[term] == pytest.approx(plain_fit[term], rel=1e-3), term
    said = [line for line in result.stderr.splitlines() if f"{path.name}: time from" in line]
    assert len(said) == 1 and time_line in said[0], result.stderr
    assert "sort the rows" not in result.stderr
    assert f"{path.name}: read as an MT Manager" in result.stderr


def test_decimal_commas_a_byte_order_mark_and_a_blank_line_are_read(tmp_path: Path) -> None:
    path = write_export(tmp_path / "de.txt", generation="2019.2", delimiter=";", decimal_comma=True)
    recording = tankdaq.read(path)
    assert (
        recording.notices[0]
        == "de.txt: read as an MT Manager 2019.2.1 text export, semicolon-separated, decimal commas"
    )
    t, roll, _ = held_tilt()
    whole = recording.samples
    assert np.allclose(whole["roll_deg"], np.degrees(roll), atol=1e-6)
    assert np.allclose(np.diff(whole["time_s"]), np.diff(t))


def test_rows_before_the_filter_has_an_orientation_are_left_out_and_said(tmp_path: Path) -> None:
    path = write_export(tmp_path / "late.txt", generation="2022.2", kind="Quat", missing="NaN")
    lines = path.read_bytes().split(b"\r\n")
    first = next(k for k, line in enumerate(lines) if line.startswith(b"PacketCounter")) + 1
    for k in range(first, first + 5):
        lines[k] = b"\t".join([*lines[k].split(b"\t")[:-4], *[b"NaN"] * 4])
    path.write_bytes(b"\r\n".join(lines))
    recording = tankdaq.read(path)
    assert "late.txt: rows without an orientation not read: 5 at the start, 0 at the end" in recording.notices
    roll = held_tilt()[1]
    assert np.allclose(recording.samples["roll_deg"], np.degrees(roll[5:]), atol=1e-4)


def test_a_clock_that_wraps_at_one_day_is_unwrapped_so_whatever_the_product_says(tmp_path: Path) -> None:
    """The header's MTi-680G is a 2**32 device; a clock that wraps at one day all the same (a product
    the family table misplaces) runs forward only at one day: the data decide, and the line says so."""
    path = write_export(tmp_path / "day.txt", generation="2022.2", start_tick=864_000_000 - 20_000)
    recording = tankdaq.read(path)
    assert (np.diff(recording.samples["time_s"]) > 0).all()
    assert "day.txt: time from SampleTimeFine (10 kHz ticks, unwrapped at one day (864e6 ticks): 1 wrap)" in (
        recording.notices
    )


def test_any_column_file_gives_its_orientation_as_the_angle(tmp_path: Path) -> None:
    """Not only MT Manager's: a plain CSV of a logger's time and quaternion gives the roll, said."""
    t, roll, _ = held_tilt()
    quaternion = orientation("Quat", roll)[1]
    columns = {"time_s": t, **{f"Quat_q{k}": quaternion[:, k] for k in range(4)}}
    recording = tankdaq.read(write_csv(tmp_path / "logger.csv", columns))
    assert np.allclose(recording.samples["roll_deg"], np.degrees(roll), atol=1e-6)
    assert any("roll angle from the quaternion Quat_q0..Quat_q3" in line for line in recording.notices)


def test_a_quaternion_or_matrix_component_is_refused_as_the_angle(tmp_path: Path) -> None:
    """``--angle-col Quat_q1`` read a 10 deg decay as "1.8 deg" without a word; now one line naming the
    options that do it right, in an export and in a plain CSV of the same columns alike."""
    quat = write_export(tmp_path / "q.txt", kind="Quat")
    refused = identify(quat, "--angle-col", "Quat_q1", *MODEL)
    assert refused.exit_code == 2
    line = one_error_line(refused)
    assert "'Quat_q1' is a quaternion component, not an angle" in line
    assert "leave out --angle-col" in line and "--axis roll or --axis pitch" in line
    t, roll, _ = held_tilt()
    matrix = write_csv(
        tmp_path / "m.csv", {"time_s": t, "Mat[2][3]": np.sin(roll), "Mat[3][3]": np.cos(roll)}
    )
    refused = identify(matrix, "--angle-col", "Mat[2][3]", *MODEL)
    assert refused.exit_code == 2
    assert "'Mat[2][3]' is a rotation-matrix entry, not an angle" in one_error_line(refused)


def test_a_pitch_decay_comes_from_the_same_quaternion(tmp_path: Path) -> None:
    """``--axis pitch`` takes the quaternion's pitch (the roll held at 1.5 deg beside it)."""
    path = write_export(tmp_path / "q.txt", kind="Quat", axis="pitch")
    result = identify(path, "--axis", "pitch", *MODEL, "--json")
    assert fitted(result)["c1"] == pytest.approx(TRUTH["c1"], rel=0.01)
    assert "pitch angle from the quaternion Quat_q0..Quat_q3" in result.stderr


def test_an_export_without_orientation_says_so(tmp_path: Path) -> None:
    path = write_export(tmp_path / "imu.txt", kind="Quat")
    lines = [line.rsplit(b"\t", 1)[0] for line in path.read_bytes().split(b"\r\n")]  # no Quat_q3
    path.write_bytes(b"\r\n".join(lines))
    result = identify(path, *MODEL)
    assert result.exit_code == 2
    assert "no orientation in this MT Manager 2022.2.0 text export" in one_error_line(result)


def test_an_export_without_time_or_rate_asks_for_rate(tmp_path: Path) -> None:
    path = write_export(tmp_path / "norate.txt", generation="2022.2", sample_time=False, missing="NaN")
    result = identify(path, *MODEL)
    assert result.exit_code == 2
    line = one_error_line(result)
    assert "no SampleTimeFine values and no update rate in its header" in line and "--rate HZ" in line


def test_a_row_with_more_fields_than_the_header_is_one_line(tmp_path: Path) -> None:
    path = write_export(tmp_path / "joined.txt", generation="4.x")
    lines = path.read_bytes().split(b"\r\n")
    lines[100] += b"\t1.0\t2.0"
    path.write_bytes(b"\r\n".join(lines))
    result = identify(path, *MODEL)
    assert result.exit_code == 2
    assert "joined.txt: line 101 has 12 fields, the header 10 (tab-separated)" in one_error_line(result)


def test_an_export_of_its_header_alone_is_one_line(tmp_path: Path) -> None:
    path = write_export(tmp_path / "head.txt", generation="4.x")
    path.write_bytes(b"\r\n".join(path.read_bytes().split(b"\r\n")[:6]))  # the block and the header
    result = identify(path, *MODEL)
    assert result.exit_code == 2
    assert "head.txt: an MT Manager export with no data rows after its header line" in one_error_line(result)


def test_an_explicit_sample_time_column_is_unwrapped_too(tmp_path: Path) -> None:
    """``--time-col SampleTimeFine`` over a 2**32 wrap said "does not increase ... sort the rows by
    time": the rows were in order, the device's clock had wrapped."""
    path = write_export(tmp_path / "wrap.csv", delimiter=",", start_tick=2**32 - 30_000, modulus=2**32)
    result = identify(path, "--time-col", "SampleTimeFine", "--angle-col", "Roll", *MODEL, "--json")
    assert fitted(result)["c1"] == pytest.approx(TRUTH["c1"], rel=0.01)
    assert "sort the rows" not in result.stderr and "time unit: tick" in result.stderr
    counted = tankdaq.read(path, time_col="PacketCounter", angle_col="Roll", sample_rate_hz=100.0)
    assert (np.diff(counted.samples["time_s"]) > 0).all()  # the counter wraps at 2**16 (from 65000)
    assert (
        "wrap.csv: time from PacketCounter at --rate 100 Hz (--time-col PacketCounter; counter wrapped at "
        "2^16 1 time, 0 packets missing)" in counted.notices
    )


def test_the_headers_facts_are_the_runs_metadata(tmp_path: Path) -> None:
    """Device id, product, firmware, filter profile and MT Manager version: in ``identify --json``, in
    ``tankdaq.read``'s metadata, and in the catalogue's row of the file."""
    folder = tmp_path / "exports"
    folder.mkdir()
    path = write_export(folder / "run.txt", generation="2022.2", kind="Quat")
    result = identify(path, *MODEL, "--json")
    source = json.loads(result.stdout)["runs"][0]["source"]
    assert source == {
        "source_format": "MT Manager 2022.2.0 text export",
        "device_id": "00B42D4B",
        "product_code": "MTi-680G",
        "firmware": "1.12.0",
        "hardware": "1.1.0",
        "filter_profile": "General(11.1)",
        "option_flags": "Orientation Smoother Disabled, AHS Disabled, ICC Disabled",
        "mt_manager_version": "2022.2.0",
        "xda_version": "2022.2.0 build 7381 rev 124627 built on 2023-07-19",
        "coordinate_system": "ENU",
    }
    meta = tankdaq.read(path).meta
    assert (meta["device_id"], meta["product_code"], meta["filter_profile"]) == (
        "00B42D4B",
        "MTi-680G",
        "General(11.1)",
    )
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    with open_catalogue(url) as catalogue:
        assert len(index_folder(catalogue, folder).added) == 1
    with open_catalogue(url) as catalogue, catalogue.engine.connect() as connection:
        (row,) = [dict(r._mapping) for r in connection.execute(sa.select(decays))]
    assert (row["device_id"], row["firmware"], row["axis"]) == ("00B42D4B", "1.12.0", "roll")


def test_v4_update_rate_is_metadata_and_read_says_the_generation(tmp_path: Path) -> None:
    path = write_export(tmp_path / "old.txt", generation="4.x", kind="Mat", sample_time=False)
    recording = tankdaq.read(path)
    assert recording.meta["update_rate_hz"] == 100.0 and recording.meta["firmware"] == "4.0.2"
    assert recording.meta["format"] == "text table"
    assert any("MT Manager 4.x text export, tab-separated" in line for line in recording.notices)


def test_the_conversions_match_a_real_mt_manager_2022_export() -> None:
    """One row of a real MT Manager 2022.2.0 export holding Quat, Roll/Pitch/Yaw and Mat columns of the
    same sample (opensim-core, ``OpenSim/Tests/shared/IMUData/Xsens/
    MT2022_ACC_GYRO_ROT_ALL_TAB_NAN_00B42D4B.txt``, first row): the quaternion and the matrix, read by
    their MT Manager names, give its own roll and pitch (6 decimals written: 1e-4 deg)."""
    roll, pitch = -0.036609, -0.590193
    quaternion = [-0.529130, 0.004539, 0.002454, 0.848525]
    names = [f"Mat[{i}][{j}]" for j in (1, 2, 3) for i in (1, 2, 3)]
    entries = [-0.440001, -0.897938, 0.010301, 0.897983, -0.440030, -0.000639, 0.005106, 0.008969, 0.999947]
    matrix = np.zeros(9)
    for name, value in zip(names, entries, strict=True):
        matrix[matrix_index(name)] = value
    for angles in (euler_from_quaternion(quaternion), euler_from_matrix(matrix)):
        assert math.degrees(angles[0]) == pytest.approx(roll, abs=1e-4)
        assert math.degrees(angles[1]) == pytest.approx(pitch, abs=1e-4)
