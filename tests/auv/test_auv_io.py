"""AUV records on disk: MCAP read back with mcap's own reader, CSV, and bad files."""

from __future__ import annotations

import json
import tomllib
from dataclasses import replace

import numpy as np
import pytest
from mcap.reader import make_reader

from tankdaq.auv.io import (
    FIELDS,
    METADATA_NAME,
    TOPIC,
    read_record,
    read_vehicle_attachment,
    write_record,
)
from tankdaq.auv.model import STATE_COLUMNS, add_noise, simulate_zigzag
from tankdaq.auv.vehicle import load_vehicle
from tankdaq.errors import BadRecordingInput, InputError


@pytest.fixture(scope="module")
def record():
    vehicle = load_vehicle("remus100")
    clean = simulate_zigzag(vehicle, np.radians(10.0), np.radians(5.0), switches=3, rate_hz=20.0)
    noisy = add_noise(clean, 1.0, seed=5)
    noisy.meta["noise"] = "1 x realistic"
    return noisy


def test_mcap_holds_the_channel_metadata_and_vehicle_attachment(tmp_path, record):
    path = write_record(tmp_path / "zigzag.mcap", record, load_vehicle("remus100"))
    with path.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        channels = list(summary.channels.values())
        assert [c.topic for c in channels] == [TOPIC]
        channel = channels[0]
        assert channel.message_encoding == "json"
        assert channel.metadata["q"] == "rad/s" and channel.metadata["theta"] == "rad"
        schema = summary.schemas[channel.schema_id]
        assert schema.encoding == "jsonschema"
        assert set(json.loads(schema.data)["required"]) == set(FIELDS)
        messages = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=[TOPIC])]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = list(reader.iter_attachments())
    assert len(messages) == record.t.size
    assert messages[10]["theta"] == pytest.approx(record["theta"][10], abs=0)
    meta = metadata[METADATA_NAME]
    assert meta["vehicle"] == "remus100" and meta["manoeuvre"] == "zigzag" and meta["delta_deg"] == "10"
    assert meta["theta_deg"] == "5" and meta["noise"] == "1 x realistic"
    assert meta["software"].startswith("tankdaq")
    assert all(isinstance(v, str) for v in meta.values())
    assert len(attachments) == 1 and attachments[0].media_type == "application/toml"
    assert tomllib.loads(attachments[0].data.decode())["derivatives"]["M_q|q|"] == -188.0


def test_mcap_round_trip_through_the_tankdaq_reader(tmp_path, record):
    path = write_record(tmp_path / "zigzag.mcap", record, load_vehicle("remus100"))
    back = read_record(path)
    assert np.array_equal(back.t, record.t)
    for column in STATE_COLUMNS:
        assert np.array_equal(back[column], record[column])
    assert back.meta["vehicle"] == "remus100"
    vehicle = read_vehicle_attachment(path)
    assert vehicle.derivatives == load_vehicle("remus100").derivatives


def test_csv_round_trip_keeps_values_and_metadata(tmp_path, record):
    path = write_record(tmp_path / "zigzag.csv", record)
    text = path.read_text().splitlines()
    assert "# vehicle: remus100" in text and "t_s,u_m_s,w_m_s,q_rad_s,theta_rad,z_m,x_m,delta_s_rad" in text
    back = read_record(path)
    for column in STATE_COLUMNS:
        assert np.allclose(back[column], record[column], rtol=1e-15, atol=0)
    assert back.meta["theta_deg"] == "5"
    assert read_vehicle_attachment(path) is None


def test_unknown_suffix_missing_file_and_garbage_are_one_line_input_errors(tmp_path, record):
    with pytest.raises(InputError, match=r"\.mcap or \.csv"):
        write_record(tmp_path / "zigzag.parquet", record)
    with pytest.raises(BadRecordingInput, match="no such file"):
        read_record(tmp_path / "absent.mcap")
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not an mcap file at all")
    with pytest.raises(BadRecordingInput, match="not a readable MCAP"):
        read_record(garbage)


def test_csv_without_a_needed_channel_names_it(tmp_path):
    path = tmp_path / "partial.csv"
    path.write_text("t_s,u_m_s,w_m_s,theta_rad,z_m,x_m,delta_s_rad\n0,1.5,0,0,0,0,0\n0.1,1.5,0,0,0,0.15,0\n")
    with pytest.raises(BadRecordingInput, match="'q'") as info:
        read_record(path)
    assert info.value.exit_code == 2


def test_a_vehicle_without_a_file_travels_as_json(tmp_path, record):
    vehicle = replace(load_vehicle("nps_auv2").with_derivatives({"M_uw": 0.11}), path=None)
    path = write_record(tmp_path / "modified.mcap", record, vehicle)
    back = read_vehicle_attachment(path)
    assert back.coefficient("M_uw") == 0.11 and back.thrust_n == pytest.approx(vehicle.thrust_n)
    assert back.derivatives == vehicle.derivatives
