"""Corruption is told from truncation (issue 37, item 11): a closed recording whose chunks in the middle
are garbled (a bad sector; footer and summary intact) is named corrupted, with its damaged chunks, and
every intact chunk is read; a file cut short (no footer) still reads as its writer never closed it.

Which chunks are intact is decided by the official ``mcap`` package, chunk by chunk through the file's
own chunk index, not by tankdaq's reader."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from typer.testing import CliRunner

from tankdaq.catalogue.rows import recording_row
from tankdaq.cli import app
from tankdaq.samples import empty_samples
from tankdaq.store import schemas
from tankdaq.store.reader import read_recording
from tankdaq.store.record_scan import MCAP_DAMAGE
from tankdaq.store.writer import RecordingWriter

runner = CliRunner()
RATE_HZ, PER_BATCH, BATCHES = 100, 10, 300
HOST_T0_S = 1.7e9


@pytest.fixture(scope="module")
def closed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A closed recording of 30 s in small chunks, its sample blocks flushed every 2.5 s (as ``record``
    flushes them), released once after 2 s."""
    path = tmp_path_factory.mktemp("closed") / "swath_T_roll_5deg_run01.mcap"
    meta = {"hull": "swath", "draft": "T", "axis": "roll"}
    with RecordingWriter(path, meta, {"rate_hz": RATE_HZ}, chunk_size=16 * 1024) as writer:
        for batch in range(BATCHES):
            samples = empty_samples(PER_BATCH)
            samples["t"] = (batch * PER_BATCH + np.arange(PER_BATCH)) / RATE_HZ
            samples["counter"] = batch * PER_BATCH + np.arange(PER_BATCH)
            samples["roll"] = 0.1 * np.exp(-0.05 * samples["t"]) * np.cos(3 * samples["t"])
            samples["p"] = -0.3 * np.exp(-0.05 * samples["t"]) * np.sin(3 * samples["t"])
            samples["host_t"] = HOST_T0_S + samples["t"]
            writer.write_raw(b"\xfa\xff\x36" + bytes(37), host_ns=int((HOST_T0_S + samples["t"][0]) * 1e9))
            writer.write_samples(samples)
            if batch == 20:
                writer.write_event("release", "release", t_s=float(samples["t"][0]))
            if batch % 25 == 24:
                writer.flush()
    return path


def chunks_of(path: Path) -> list[tuple[int, set[str]]]:
    """(offset, topics) of every chunk, in file order, from the file's summary (official reader)."""
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    indexes = sorted(summary.chunk_indexes, key=lambda index: index.chunk_start_offset)
    return [
        (index.chunk_start_offset, {summary.channels[c].topic for c in index.message_index_offsets})
        for index in indexes
    ]


def intact_sample_times(path: Path) -> tuple[list[int], np.ndarray]:
    """The chunks the official reader cannot open (their numbers, 1-based), and the device times of the
    per-sample messages of every chunk it can."""
    damaged, times = [], []
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None
        samples_id = next(c.id for c in summary.channels.values() if c.topic == schemas.TOPIC_SAMPLES)
        indexes = sorted(summary.chunk_indexes, key=lambda index: index.chunk_start_offset)
        for number, index in enumerate(indexes, start=1):
            stream.seek(index.chunk_start_offset)
            try:
                chunk = next(
                    StreamReader(stream, skip_magic=True, emit_chunks=True, validate_crcs=True).records
                )
                assert isinstance(chunk, Chunk)
                records = breakup_chunk(chunk, validate_crc=True)
            except (McapError, *MCAP_DAMAGE):
                damaged.append(number)
                continue
            times += [
                schemas.samples_from_json([r.data], [r.log_time])["t"][0]
                for r in records
                if isinstance(r, Message) and r.channel_id == samples_id
            ]
    return damaged, np.sort(np.asarray(times))


#: Noise written over a chunk, and where: inside its compressed records, or over its record header (opcode
#: and length: the file's framing is lost there, and only the summary's index finds the next chunk).
BAD_SECTORS = {
    "records": (300, np.random.default_rng(37).integers(0, 256, 200, dtype=np.uint8).tobytes()),
    "header": (0, bytes([0xAD]) + (2**62 + 12345).to_bytes(8, "little")),
}


@pytest.fixture(scope="module", params=sorted(BAD_SECTORS))
def corrupted(
    closed: Path, tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest
) -> tuple[Path, list[int]]:
    """The closed recording with one chunk of samples (where ``request.param`` says) and one of sample
    blocks (inside its records) garbled, a third of the way in: the chunk numbers (1-based) garbled."""
    path = tmp_path_factory.mktemp("corrupted") / closed.name
    shutil.copyfile(closed, path)
    chunks = chunks_of(path)
    data = [n for n, (_, topics) in enumerate(chunks, 1) if schemas.TOPIC_SAMPLES in topics]
    blocks = [n for n, (_, topics) in enumerate(chunks, 1) if topics == {schemas.TOPIC_SAMPLE_BLOCKS}]
    chosen = [data[len(data) // 3], blocks[len(blocks) // 3]]
    with path.open("r+b") as out:
        for number, where in zip(chosen, [request.param, "records"], strict=True):
            skip, noise = BAD_SECTORS[where]
            out.seek(chunks[number - 1][0] + skip)
            out.write(noise)
    return path, chosen


@pytest.mark.slow
def test_every_intact_chunk_is_read_and_the_damaged_ones_named(corrupted: tuple[Path, list[int]]) -> None:
    path, garbled = corrupted
    damaged, expected_t = intact_sample_times(path)
    assert damaged == garbled  # the official reader agrees which chunks the bad sector hit
    recording = read_recording(path)
    np.testing.assert_array_equal(recording.samples["t"], expected_t)  # every row of every intact chunk
    assert 0 < BATCHES * PER_BATCH - expected_t.size < 0.1 * BATCHES * PER_BATCH
    assert recording.complete and recording.corruption is not None
    notice = recording.notice
    assert notice is not None and "corrupted, not cut short" in notice and "never closed" not in notice
    total = len(chunks_of(path))
    for number in garbled:
        assert f"chunk {number} of {total}" in notice
    assert notice.count("chunk ") == len(garbled) + 1  # those, and "every other chunk was read"


def test_the_intact_file_reads_whole(closed: Path) -> None:
    recording = read_recording(closed)
    assert recording.samples.size == BATCHES * PER_BATCH and recording.notice is None


def test_a_file_cut_short_still_reads_as_never_closed(closed: Path, tmp_path: Path) -> None:
    cut = tmp_path / closed.name
    cut.write_bytes(closed.read_bytes()[: closed.stat().st_size // 2])
    recording = read_recording(cut)
    assert not recording.complete and recording.corruption is None
    assert recording.notice is not None and "never closed" in recording.notice
    assert 0 < recording.samples.size < BATCHES * PER_BATCH


@pytest.mark.slow
def test_identify_says_corrupted_in_one_line(corrupted: tuple[Path, list[int]]) -> None:
    path, _ = corrupted
    result = runner.invoke(app, ["identify", str(path), "--model", "b1,c1"])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.output.splitlines() if str(path) in line and "corrupted" in line]
    assert len(warnings) == 1 and "never closed" not in result.output


@pytest.mark.slow
def test_recover_keeps_every_intact_chunk_and_says_corrupted(
    corrupted: tuple[Path, list[int]], tmp_path: Path
) -> None:
    path, _ = corrupted
    out = tmp_path / "recovered.mcap"
    result = runner.invoke(app, ["recover", str(path), "--out", str(out)])
    assert result.exit_code == 3  # lossy, as mcap recover says it
    assert "corrupted, not cut short" in result.output and "truncated" not in result.output
    _, expected_t = intact_sample_times(path)
    recovered = read_recording(out)
    assert recovered.notice is None
    np.testing.assert_array_equal(recovered.samples["t"], expected_t)


@pytest.mark.slow
def test_the_catalogue_row_is_not_complete(corrupted: tuple[Path, list[int]], closed: Path) -> None:
    """As a file cut short: ``recover`` then ``index`` gives the complete copy its row."""
    assert recording_row(corrupted[0])[0]["complete"] is False
    assert recording_row(closed)[0]["complete"] is True


@pytest.mark.slow
def test_export_says_corrupted(corrupted: tuple[Path, list[int]], tmp_path: Path) -> None:
    path, _ = corrupted
    result = runner.invoke(app, ["export", str(path), "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "corrupted, not cut short" in result.stderr and "never closed" not in result.stderr


@pytest.mark.slow
def test_index_names_a_corrupted_recording_as_not_complete(
    corrupted: tuple[Path, list[int]], tmp_path: Path
) -> None:
    folder = tmp_path / "folder"
    folder.mkdir()
    copy = Path(shutil.copy(corrupted[0], folder / corrupted[0].name))
    catalogue = str(tmp_path / "catalogue.sqlite")
    result = runner.invoke(app, ["catalogue", "index", str(folder), "--catalogue", catalogue])
    assert result.exit_code == 0, result.output
    assert f"not complete (cut short or corrupted): {copy}" in result.stderr
    assert "1 added" in result.stdout
