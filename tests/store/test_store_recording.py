"""RecordingWriter -> reader round trips on real MCAP files, names, and refusals of bad input."""

from __future__ import annotations

import json
import os
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from support.xsens_captures import capture as real_capture
from tankdaq.config.hulls import load_hull
from tankdaq.errors import BadRecordingInput, InputError, RecordingError
from tankdaq.physics.decay import simulate_decay
from tankdaq.physics.terms import TERM_TABLE
from tankdaq.samples import SAMPLE_DTYPE
from tankdaq.store import schemas
from tankdaq.store.naming import (
    RecordingLabels,
    create_exclusive,
    next_run_number,
    parse_recording_name,
    recording_name,
)
from tankdaq.store.reader import StoredRecording, iter_raw_chunks, read_decay_runs, read_recording
from tankdaq.store.reader import _read_indexed as read_recording_indexed
from tankdaq.store.reader import _read_scanned as read_recording_scanned
from tankdaq.store.writer import RecordingWriter, describe_run

RATE_HZ = 200.0
RELEASE_T_S = 2.0
TRUTH = {"b1": 0.8, "b2": 0.6, "c1": 40.0, "c3": -15.0}
ANGLE0_RAD = np.radians(8.0)
RUN_METADATA = {
    "hull": "swath",
    "draft": "1.1T",
    "axis": "roll",
    "angle_nominal_deg": 8.0,
    "operator": "test",
    "hull_length_m": 1.2,
}
RUN_CONFIG = {"port": "/dev/ttyUSB0", "rate_hz": RATE_HZ, "model": ["b1", "b2", "c1", "c3"]}


def decay_samples(seconds: float = 8.0) -> np.ndarray:
    """Held at 8 deg until RELEASE_T_S, then a known-truth decay; other fields random but reproducible."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, seconds, 1 / RATE_HZ)
    after = t >= RELEASE_T_S
    angle = np.full(t.size, ANGLE0_RAD)
    rate = np.zeros(t.size)
    if after.any():
        angle[after], rate[after] = simulate_decay(TRUTH, t[after], ANGLE0_RAD)
    samples = np.zeros(t.size, dtype=SAMPLE_DTYPE)
    samples["t"] = t
    samples["ticks"] = np.round(t * 1e4).astype(np.int64)
    samples["host_t"] = 1.79e9 + t + rng.uniform(0, 1e-3, t.size)
    samples["counter"] = np.arange(t.size) % 65536
    samples["roll"], samples["p"] = angle, rate
    for name in ("pitch", "yaw", "q", "r", "ax", "ay"):
        samples[name] = rng.normal(0, 0.05, t.size)
    samples["az"] = 9.81 + rng.normal(0, 0.01, t.size)
    samples["status"] = rng.integers(0, 2**32, t.size, dtype=np.uint64).astype(np.uint32)
    return samples


def write_recording(path: Path, samples: np.ndarray, raw: list[tuple[int, bytes]]) -> Path:
    with RecordingWriter(path, RUN_METADATA, RUN_CONFIG) as writer:
        for (host_ns, data), block in zip(raw, np.array_split(samples, len(raw)), strict=True):
            writer.write_raw(data, host_ns=host_ns)
            writer.write_samples(block)
            if block["t"][0] <= RELEASE_T_S < block["t"][-1] + 1 / RATE_HZ:
                writer.write_event(
                    "release", "released by hand", t_s=RELEASE_T_S, data={"threshold_deg_s": 2.0}
                )
        writer.write_event("warning", "roll exceeded 7.5 deg before release", t_s=1.0)
        writer.write_fit(
            5.0,
            {"c1": 39.0, "b1": 0.7},
            std={"b1": 0.05, "c1": 0.4},
            ci95={"b1": 0.1, "c1": [38, 40]},
            r2=0.98,
        )
        writer.write_event("settled", "below 0.5 deg", t_s=7.5)
    return writer.path


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray, list[tuple[int, bytes]]]:
    rng = np.random.default_rng(3)
    samples = decay_samples()
    raw = [
        (1_790_000_000_000_000_000 + k * 10_000_000, rng.bytes(int(rng.integers(1, 300)))) for k in range(40)
    ]
    raw[3] = (raw[3][0], b"\xfa\xff\x36\x00" + bytes(range(256)))  # every byte value survives
    path = write_recording(tmp_path_factory.mktemp("rec") / "run.mcap", samples, raw)
    return path, samples, raw


def test_samples_round_trip_to_float_precision(recording: tuple[Path, np.ndarray, list]) -> None:
    path, samples, _ = recording
    back = read_recording(path).samples
    assert back.dtype == SAMPLE_DTYPE and back.size == samples.size
    for name in ("ticks", "counter", "status"):
        np.testing.assert_array_equal(back[name], samples[name])
    for name in ("t", "roll", "pitch", "yaw", "p", "q", "r", "ax", "ay", "az"):
        np.testing.assert_allclose(back[name], samples[name], rtol=1e-15, atol=0, err_msg=name)
    np.testing.assert_allclose(back["host_t"], samples["host_t"], rtol=0, atol=1e-6)


def test_raw_chunks_are_byte_identical(recording: tuple[Path, np.ndarray, list]) -> None:
    path, _, raw = recording
    assert read_recording(path).raw_chunks == raw
    assert list(iter_raw_chunks(path)) == raw


def test_events_fits_metadata_and_attachment(recording: tuple[Path, np.ndarray, list]) -> None:
    path, samples, _ = recording
    rec = read_recording(path)
    assert rec.complete
    assert [e["kind"] for e in rec.events] == ["release", "warning", "settled"]
    assert rec.events[0] == {
        "t_s": RELEASE_T_S,
        "kind": "release",
        "message": "released by hand",
        "data": {"threshold_deg_s": 2.0},
    }
    (fit,) = rec.fits
    assert fit["terms"] == ["b1", "c1"]  # canonical order, whatever order was given
    assert fit["coefficients"] == {"b1": 0.7, "c1": 39.0}
    assert fit["ci95"] == {"b1": pytest.approx([0.6, 0.8]), "c1": [38.0, 40.0]}
    assert fit["r2"] == 0.98
    assert rec.run_config == json.loads(json.dumps(RUN_CONFIG))

    start, final = rec.metadata_history
    assert "closed_utc" not in start and start["hull"] == "swath"
    assert rec.metadata is not start and rec.metadata == final
    assert final["draft"] == "1.1T" and final["axis"] == "roll" and float(final["angle_nominal_deg"]) == 8.0
    assert final["hull_length_m"] == "1.2"
    assert int(final["samples"]) == samples.size
    assert float(final["measured_sample_rate_hz"]) == pytest.approx(RATE_HZ)
    assert float(final["release_t_s"]) == RELEASE_T_S
    assert float(final["angle_initial_deg"]) == pytest.approx(8.0, abs=1e-9)
    assert json.loads(final["warnings"]) == ["roll exceeded 7.5 deg before release"]
    assert rec.release_index == int(np.flatnonzero(samples["t"] >= RELEASE_T_S)[0])


def test_file_is_indexed_mcap_that_foxglove_can_plot(recording: tuple[Path, np.ndarray, list]) -> None:
    path, samples, _ = recording
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: c for c in summary.channels.values()}
        raw = channels[schemas.TOPIC_RAW]
        assert raw.schema_id == 0 and raw.message_encoding == "xbus"
        for topic in (schemas.TOPIC_SAMPLES, schemas.TOPIC_EVENTS, schemas.TOPIC_FIT):
            schema = summary.schemas[channels[topic].schema_id]
            assert channels[topic].message_encoding == "json" and schema.encoding == "jsonschema"
            assert json.loads(schema.data)["type"] == "object"
        assert "deg" in json.loads(channels[schemas.TOPIC_SAMPLES].metadata["units"])["roll_deg"]
        sample_schema = json.loads(summary.schemas[channels[schemas.TOPIC_SAMPLES].schema_id].data)
        messages = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=[schemas.TOPIC_SAMPLES])]
    assert len(messages) == samples.size
    assert set(messages[0]) == set(sample_schema["required"])
    assert messages[500]["roll_deg"] == pytest.approx(np.degrees(samples["roll"][500]), rel=1e-15)
    assert isinstance(messages[500]["counter"], int)


FOXGLOVE_SCALARS = {"boolean", "string", "number", "integer"}


def assert_foxglove_parses(schema: dict, where: str) -> None:
    """Foxglove's parseJsonSchema (mcap-support) rules: one type name per field, objects with properties."""
    assert schema["type"] == "object", where
    for name, field in schema["properties"].items():
        path = f"{where}.{name}"
        assert isinstance(field.get("type"), str), f"{path}: type must be one name, got {field.get('type')!r}"
        if field["type"] == "object":
            assert_foxglove_parses(field, path)
        elif field["type"] == "array":
            item = field["items"]
            assert isinstance(item.get("type"), str), path
            if item["type"] == "object":
                assert_foxglove_parses(item, path)
            else:
                assert item["type"] in FOXGLOVE_SCALARS, path
        else:
            assert field["type"] in FOXGLOVE_SCALARS, path


def test_schemas_parse_in_foxglove_and_fit_terms_are_plottable() -> None:
    for body in (schemas.SAMPLES_SCHEMA, schemas.EVENTS_SCHEMA, schemas.FIT_SCHEMA):
        schema = json.loads(body)
        assert_foxglove_parses(schema, schema["title"])
    fit = json.loads(schemas.FIT_SCHEMA)
    assert set(fit["properties"]["coefficients"]["properties"]) == set(TERM_TABLE)  # .fc plots too


def without_sample_blocks(source: Path, destination: Path) -> Path:
    """The file as tankdaq wrote it before sample blocks: every record but the /samples/blocks channel."""
    with source.open("rb") as stream, destination.open("wb") as out:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        writer = Writer(out)
        writer.start()
        channel_ids: dict[int, int] = {}
        for channel in summary.channels.values():
            if channel.topic == schemas.TOPIC_SAMPLE_BLOCKS:
                continue
            schema = summary.schemas.get(channel.schema_id)
            schema_id = writer.register_schema(schema.name, schema.encoding, schema.data) if schema else 0
            channel_ids[channel.id] = writer.register_channel(
                channel.topic, channel.message_encoding, schema_id, dict(channel.metadata)
            )
        for metadata in reader.iter_metadata():
            writer.add_metadata(metadata.name, dict(metadata.metadata))
        for attachment in reader.iter_attachments():
            writer.add_attachment(
                attachment.log_time,
                attachment.create_time,
                attachment.name,
                attachment.media_type,
                attachment.data,
            )
        for _, channel, message in reader.iter_messages(log_time_order=False):
            if channel.id in channel_ids:
                writer.add_message(
                    channel_ids[channel.id], message.log_time, message.data, message.publish_time
                )
        writer.finish()
    return destination


def assert_same_recording(read: StoredRecording, expected: StoredRecording) -> None:
    assert read.samples.dtype == expected.samples.dtype
    for name in SAMPLE_DTYPE.names:  # bit for bit, NaN in the same places
        np.testing.assert_array_equal(read.samples[name], expected.samples[name], err_msg=name)
    assert read.events == expected.events and read.fits == expected.fits
    assert read.metadata_history == expected.metadata_history and read.attachments == expected.attachments
    assert read.release_index == expected.release_index and read.raw_chunks == expected.raw_chunks


def test_sample_blocks_read_the_same_as_the_per_sample_messages(
    recording: tuple[Path, np.ndarray, list], tmp_path: Path
) -> None:
    """The fast path (index + blocks) and the front-to-back scan of the JSON give the same recording."""
    path, _, _ = recording
    assert read_recording_indexed(path) is not None  # this file does take the fast path
    assert_same_recording(read_recording(path), read_recording_scanned(path))
    samples = decay_samples(1.0)
    samples["pitch"][[3, 4]] = np.nan
    samples["yaw"][5] = -np.inf
    gaps = write_recording(tmp_path / "gaps.mcap", samples, [(1, b"x")])
    assert_same_recording(read_recording(gaps), read_recording_scanned(gaps))


def test_files_recorded_before_sample_blocks_still_read(
    recording: tuple[Path, np.ndarray, list], tmp_path: Path
) -> None:
    path, _, _ = recording
    old = without_sample_blocks(path, tmp_path / "old.mcap")
    with old.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    assert schemas.TOPIC_SAMPLE_BLOCKS not in {c.topic for c in summary.channels.values()}
    assert read_recording_indexed(old) is None
    back = read_recording(old)
    assert_same_recording(back, read_recording(path))
    assert [run.angle.size for run in read_decay_runs(old)] == [
        run.angle.size for run in read_decay_runs(path)
    ]


def test_missing_values_become_null_and_come_back_as_nan(tmp_path: Path) -> None:
    samples = decay_samples(1.0)
    samples["pitch"][[3, 4]] = np.nan
    samples["yaw"][5] = np.inf
    path = write_recording(tmp_path / "gaps.mcap", samples, [(1, b"x")])
    with path.open("rb") as stream:
        texts = [m.data for _, _, m in make_reader(stream).iter_messages(topics=[schemas.TOPIC_SAMPLES])]
    assert json.loads(texts[3])["pitch_deg"] is None  # valid JSON, not NaN
    back = read_recording(path).samples
    assert np.isnan(back["pitch"][[3, 4]]).all() and np.isnan(back["yaw"][5])
    assert np.isfinite(back["pitch"][5])


def test_decay_runs_start_at_the_release(recording: tuple[Path, np.ndarray, list]) -> None:
    path, samples, _ = recording
    (run,) = read_decay_runs(path)
    after = samples["t"] >= RELEASE_T_S
    assert run.axis == "roll" and run.t[0] == pytest.approx(RELEASE_T_S)
    np.testing.assert_allclose(run.angle, samples["roll"][after], rtol=1e-15)
    np.testing.assert_allclose(run.rate, samples["p"][after], rtol=1e-15)
    assert run.meta["hull"] == "swath" and run.meta["draft"] == 1.1 and run.meta["angle_nominal_deg"] == 8.0
    assert run.meta["file"] == str(path)
    (pitch_run,) = read_decay_runs(path, axis="pitch")
    np.testing.assert_allclose(pitch_run.angle, samples["pitch"][after], rtol=1e-15)
    with pytest.raises(InputError, match="axis 'yaw'"):
        read_decay_runs(path, axis="yaw")


def test_no_release_event_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "norelease.mcap"
    with RecordingWriter(path, {"axis": "roll"}, {}) as writer:
        writer.write_samples(decay_samples(1.0))
    with pytest.raises(BadRecordingInput, match="no release event"):
        read_decay_runs(path)


def test_not_mcap_and_foreign_mcap_are_refused(tmp_path: Path) -> None:
    text = tmp_path / "notes.mcap"
    text.write_text("time,roll\n0,1\n")
    empty = tmp_path / "empty.mcap"
    empty.touch()
    foreign = tmp_path / "camera.mcap"
    with foreign.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        channel = writer.register_channel("/camera/image", "raw", 0)
        writer.add_message(channel, 1, b"pixels", 1)
        writer.finish()
    for path, message in (
        (text, "not an MCAP file"),
        (empty, "is empty"),
        (foreign, "not a tankdaq recording .*?/camera/image"),
        (tmp_path / "missing.mcap", "no such recording"),
    ):
        with pytest.raises(BadRecordingInput, match=message) as info:
            read_recording(path)
        assert "\n" not in str(info.value) and info.value.exit_code == 2


def test_existing_files_are_never_overwritten(tmp_path: Path) -> None:
    first = tmp_path / "run.mcap"
    first.write_bytes(b"precious")
    with RecordingWriter(first, {}, {}) as writer:
        writer.write_raw(b"abc")
    assert writer.path == tmp_path / "run-2.mcap"
    assert first.read_bytes() == b"precious"
    path, fd = create_exclusive(first)
    os.close(fd)
    assert path == tmp_path / "run-3.mcap"


def test_names_say_what_a_person_looks_for(tmp_path: Path) -> None:
    when = datetime(2026, 11, 21, 14, 30, 15)
    assert (
        recording_name("swath", 1.1, "roll", 8, 3, when) == "swath_1.1T_roll_8deg_20261121-143015_run03.mcap"
    )
    assert (
        recording_name("swath", "T", "pitch", 7.5, 12, when)
        == "swath_T_pitch_7.5deg_20261121-143015_run12.mcap"
    )
    assert next_run_number(tmp_path, "swath", 1.1, "roll") == 1
    (tmp_path / recording_name("swath", 1.1, "roll", 8, 3, when)).touch()
    (tmp_path / "swath_1.1T_roll_8deg_20261121-143015_run07-2.mcap").touch()
    (tmp_path / recording_name("swath", 0.9, "roll", 8, 9, when)).touch()  # another draft: not counted
    assert next_run_number(tmp_path, "swath", 1.1, "roll") == 8


def test_the_name_grammar_reads_back_what_it_writes() -> None:
    when = datetime(2026, 11, 21, 14, 30, 15)
    written = (("swath", 1.1, "roll", 8.0, 3), ("kvlcc2_model", 1.0, "pitch", 7.5, 12))
    for hull, draft, axis, angle, run in written:
        labels = parse_recording_name(recording_name(hull, draft, axis, angle, run, when))
        assert labels == RecordingLabels(hull, draft, axis, angle, "20261121-143015", run)
    by_hand = parse_recording_name("trimaran_0.9T_pitch_8deg.csv")
    assert by_hand == RecordingLabels("trimaran", 0.9, "pitch", 8.0)
    assert parse_recording_name("decay 17.csv") is None and parse_recording_name("swath_T_roll_8degx") is None


def test_one_way_in_picks_the_reader_by_suffix_and_names_the_known_ones(tmp_path: Path) -> None:
    from tankdaq.errors import InputError
    from tankdaq.store.inputs import INPUT_FORMATS, read_runs

    assert list(INPUT_FORMATS) == [
        ".mcap",
        ".csv",
        ".txt",
        ".h5",
        ".hdf5",
        ".mat",
        ".parquet",
        ".tdms",
        ".mtb",
    ]
    known = (
        r"unknown file type \.dat; decays: use a \.mcap, \.csv, \.txt, \.h5, \.hdf5, \.mat, \.parquet, "
        r"\.tdms or \.mtb file"
    )
    with pytest.raises(InputError, match=known):
        read_runs(tmp_path / "x.dat")


def test_describe_run_fills_the_ittc_keys_from_the_hull() -> None:
    hull = load_hull("catamaran")
    described = describe_run(
        "pitch",
        6.0,
        hull=hull,
        draft=1.1,
        sample_rate_hz=100,
        device={"device_id": "037003F2", "firmware": "1.8.2", "product_code": None},
        operator="kim",
    )
    assert described["hull"] == "catamaran" and described["draft"] == "1.1T" and described["axis"] == "pitch"
    assert described["hull_length_m"] == hull.dimensions["length_m"]
    assert described["device_id"] == "037003F2" and "product_code" not in described
    assert set(described) - {f"hull_{k}" for k in hull.dimensions} <= set(schemas.RUN_METADATA_KEYS)


def test_misuse_of_a_writer_is_refused(tmp_path: Path) -> None:
    writer = RecordingWriter(tmp_path / "x.mcap", {}, {})
    with pytest.raises(ValueError, match="unknown event kind 'oops'"):
        writer.write_event("oops", "")
    with pytest.raises(ValueError, match="unknown decay terms"):
        writer.write_fit(1.0, {"k9": 1.0})
    writer.close()
    writer.close()  # idempotent
    with pytest.raises(RecordingError, match="already closed"):
        writer.write_raw(b"late")
    assert read_recording(writer.path).complete


def test_a_file_cut_before_its_first_chunk_says_so(tmp_path: Path) -> None:
    path = write_recording(tmp_path / "run.mcap", decay_samples(1.0), [(1, b"x")])
    data = path.read_bytes()
    first_chunk = data.index(b"run_config.json")  # header, metadata, then the attachment, then data
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: first_chunk + 200])
    with pytest.raises(BadRecordingInput, match="cut short before its first data"):
        read_recording(cut)


def test_a_real_xsens_capture_survives_byte_for_byte(tmp_path: Path) -> None:
    capture = real_capture("einride-1").read_bytes()
    cuts = np.sort(np.random.default_rng(5).choice(np.arange(1, len(capture)), size=60, replace=False))
    pieces = [capture[a:b] for a, b in zip([0, *cuts], [*cuts, len(capture)], strict=True)]  # as serial reads
    with RecordingWriter(tmp_path / "capture.mcap", {"axis": "roll"}, {}) as writer:
        for k, piece in enumerate(pieces):
            writer.write_raw(piece, host_ns=1_000 + k)
    chunks = list(iter_raw_chunks(writer.path))
    assert b"".join(data for _, data in chunks) == capture
    assert [stamp for stamp, _ in chunks] == [1_000 + k for k in range(len(pieces))]
