"""What survives a killed writer and a full disk, and `tankdaq recover` on real damaged files.

The writers run in child processes, killed for real (SIGKILL) or limited for
real (RLIMIT_FSIZE, so the kernel answers EFBIG), and the parent reads back
what is on disk.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import MessageIndex
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.errors import BadRecordingInput
from tankdaq.records import DecayEnd
from tankdaq.store import schemas
from tankdaq.store.reader import read_decay_runs, read_recording
from tankdaq.store.record_scan import RecordScan
from tankdaq.store.recover import recover

#: A writer child: argv = mode path [path2]. Prints "batch host_ns" after each batch it handed to the writer.
CHILD = r"""
import resource, signal, sys, time
import numpy as np
from tankdaq.errors import RecordingError
from tankdaq.samples import empty_samples
from tankdaq.store.writer import RecordingWriter

RATE_HZ, PER_BATCH = 400, 4

def write(path, batches, paced):
    meta = {"hull": "swath", "draft": "T", "axis": "roll"}
    with RecordingWriter(path, meta, {"rate_hz": RATE_HZ}) as writer:
        for batch in range(batches):
            stamp = time.time_ns()
            index = batch * PER_BATCH + np.arange(PER_BATCH)
            samples = empty_samples(PER_BATCH)
            samples["t"] = index / RATE_HZ
            samples["counter"] = index % 65536
            samples["roll"] = 0.1 * np.cos(8 * samples["t"])
            samples["p"] = -0.8 * np.sin(8 * samples["t"])
            samples["host_t"] = stamp / 1e9
            writer.write_raw(b"batch %d;" % batch + bytes(40), host_ns=stamp)
            writer.write_samples(samples)
            if batch == 20:
                writer.write_event("release", "release", t_s=float(samples["t"][0]))
            print(batch, stamp, flush=True)
            if paced:
                time.sleep(0.01)

mode = sys.argv[1]
if mode == "complete":
    write(sys.argv[2], int(sys.argv[3]), paced=False)
elif mode == "forever":
    write(sys.argv[2], 10**9, paced=True)
elif mode == "disk-full":
    limit = int(sys.argv[4])
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    write(sys.argv[2], 100, paced=False)
    try:
        write(sys.argv[3], 10**6, paced=False)
    except RecordingError as exc:
        print("ERROR", exc, flush=True)
        sys.exit(exc.exit_code)
"""


def run_child(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", CHILD, *args], capture_output=True, text=True, timeout=120)


def batches_in(path: Path) -> list[int]:
    """Batch numbers of the raw chunks in a file, in file order."""
    return [int(data.split(b";")[0].split()[1]) for _, data in read_recording(path).raw_chunks]


@pytest.fixture(scope="module")
def complete_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("complete") / "run.mcap"
    result = run_child("complete", str(path), "300")
    assert result.returncode == 0, result.stderr
    return path


@pytest.mark.slow
def test_killed_writer_loses_at_most_the_last_second(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, "forever", str(path)], stdout=subprocess.PIPE, text=True
    )
    assert child.stdout is not None
    written: list[tuple[int, int]] = []
    while len(written) < 300:  # about 3 s of paced writing
        line = child.stdout.readline()
        assert line, "writer child died early"
        written.append(tuple(map(int, line.split())))  # type: ignore[arg-type]
    kill_ns = time.time_ns()
    os.kill(child.pid, signal.SIGKILL)
    written += [tuple(map(int, line.split())) for line in child.stdout]  # type: ignore[misc]
    child.wait()
    old_enough = {batch for batch, stamp in written if stamp < kill_ns - 1_000_000_000}
    assert len(old_enough) > 150

    salvaged = read_recording(path)  # the killed file itself reads, without its summary
    assert not salvaged.complete and salvaged.ended is DecayEnd.CUT

    report = recover(path)
    assert report.destination == tmp_path / "killed.recovered.mcap"
    assert report.messages > 0 and report.chunks > 0 and report.metadata == 1 and report.attachments == 1
    with report.destination.open("rb") as stream:
        reader = make_reader(stream)
        assert reader.get_summary() is not None
        messages = list(reader.iter_messages())
        metadata = list(reader.iter_metadata())
    assert len(messages) == report.messages
    # the cut file's run metadata, then again saying how the decay ended: rebuilt from a cut file (partial)
    assert [m.name for m in metadata] == [schemas.RUN_METADATA_NAME] * 2
    assert metadata[-1].metadata == {**metadata[0].metadata, "ended": "recovered"}
    assert metadata[0].metadata["hull"] == "swath" and "ended" not in metadata[0].metadata

    recovered_batches = batches_in(report.destination)
    assert recovered_batches == list(range(len(recovered_batches)))  # a gap-free prefix
    assert old_enough <= set(recovered_batches)
    recovered = read_recording(report.destination)
    counters = recovered.samples["counter"]
    np.testing.assert_array_equal(counters, np.arange(counters.size))  # samples too: a gap-free prefix
    assert counters.size >= 4 * (max(old_enough) + 1)
    np.testing.assert_array_equal(recovered.samples["roll"], salvaged.samples["roll"])
    assert [e["kind"] for e in recovered.events] == ["release"]
    assert recovered.ended is DecayEnd.RECOVERED and not recovered.ended.whole
    (run,) = read_decay_runs(report.destination)
    assert run.meta["ended"] is DecayEnd.RECOVERED


@pytest.mark.slow
def test_full_disk_is_a_recording_error_and_earlier_files_stay_readable(tmp_path: Path) -> None:
    first, second = tmp_path / "first.mcap", tmp_path / "second.mcap"
    limit = 200_000
    result = run_child("disk-full", str(first), str(second), str(limit))
    assert result.returncode == 1, result.stderr
    (error_line,) = [line for line in result.stdout.splitlines() if line.startswith("ERROR")]
    assert f"disk full writing {second}" in error_line
    assert f"free space, then run tankdaq recover {second}" in error_line
    assert "Traceback" not in result.stderr

    earlier = read_recording(first)
    assert earlier.complete and earlier.samples.size == 400 and batches_in(first) == list(range(100))

    assert second.stat().st_size == limit  # the kernel stopped the file at the limit
    damaged = read_recording(second)
    assert not damaged.complete and damaged.samples.size > 0
    report = recover(second)
    assert report.exit_code == 3 and not report.lossless
    assert batches_in(report.destination) == list(range(len(damaged.raw_chunks)))


def invoke(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["recover", *args])
    return result.exit_code, result.output


@pytest.mark.slow
def test_recover_cli_exit_codes(tmp_path: Path, complete_file: Path) -> None:
    data = complete_file.read_bytes()

    code, output = invoke(str(complete_file), "--out", str(tmp_path / "whole.mcap"))
    assert code == 0 and "nothing lost" in output
    assert batches_in(tmp_path / "whole.mcap") == list(range(300))
    whole, source = read_recording(tmp_path / "whole.mcap"), read_recording(complete_file)
    assert whole.metadata_history == source.metadata_history  # a closed file's copy: nothing said again
    assert whole.ended is source.ended is DecayEnd.SETTLED  # closed by a program that wrote it whole

    torn = tmp_path / "torn.mcap"
    torn.write_bytes(data[: len(data) * 2 // 3])
    code, output = invoke(str(torn))
    assert code == 3 and "truncated" in output
    assert (tmp_path / "torn.recovered.mcap").is_file()
    code, _ = invoke(str(torn))  # again: the first result is not overwritten
    assert code == 3 and (tmp_path / "torn.recovered-2.mcap").is_file()

    stub = tmp_path / "stub.mcap"
    stub.write_bytes(data[:120])  # magic, header and a torn metadata record: no message at all
    code, output = invoke(str(stub))
    assert code == 1 and "nothing recovered" in output
    assert not (tmp_path / "stub.recovered.mcap").exists()

    notes = tmp_path / "notes.txt"
    notes.write_text("not a recording")
    for args in ([str(notes)], [str(tmp_path / "missing.mcap")], [str(torn), "--out", str(complete_file)]):
        code, output = invoke(*args)
        assert code == 2, output
        assert output.count("\n") == 1 and output.startswith("error: ")


def test_recover_refuses_non_mcap_before_creating_anything(tmp_path: Path) -> None:
    notes = tmp_path / "notes.mcap"
    notes.write_bytes(b"\x00" * 100)
    with pytest.raises(BadRecordingInput, match="not an MCAP file"):
        recover(notes)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.mcap"]


@pytest.mark.slow
def test_lossless_means_the_cut_fell_between_records(tmp_path: Path, complete_file: Path) -> None:
    scan = RecordScan(complete_file)
    boundary = next(
        scan.bytes_read for record in scan if isinstance(record, MessageIndex)
    )  # first chunk's end
    data = complete_file.read_bytes()
    for cut, lossless in ((boundary, True), (boundary + 3, False)):
        torn = tmp_path / f"cut{cut}.mcap"
        torn.write_bytes(data[:cut])
        report = recover(torn)
        assert report.lossless is lossless and not report.source_complete
        assert report.exit_code == (0 if lossless else 3) and report.chunks == 1
