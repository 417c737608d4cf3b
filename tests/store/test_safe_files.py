"""Nothing a user wrote is ever overwritten (issue 37, item 1): exports and reports into a folder holding
a user's file of the same name, through a symbolic link, with two inputs of one name, and on a full disk
(a real small tmpfs, and the kernel's file size limit for a run without root). Afterwards the user's
files are byte-identical, no half-written file stands under a final name, no temporary file is left, and
the command said one line and exited non-zero, without a traceback or the HDF5 library's error stack."""

from __future__ import annotations

import errno
import os
import resource
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import h5py
import pandas as pd
import pytest
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.errors import InputError, RecordingError
from tankdaq.store.safe_write import write_new, write_text_new

runner = CliRunner()
TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))
FORMATS = ("csv", "h5", "parquet", "mat")
USERS = b"a user's own file: never to be touched\n"


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every entry of a folder by name: a file's bytes, a link's target."""
    return {
        p.name: (os.readlink(p).encode() if p.is_symlink() else p.read_bytes())
        for p in sorted(folder.iterdir())
    }


def one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    assert "Traceback" not in text and "HDF5" not in text
    return lines[0]


def error_line(text: str) -> str:
    """The one error line of a command that printed its progress before it (a campaign's reading)."""
    (line,) = [line for line in text.splitlines() if line.startswith("error:")]
    assert "Traceback" not in text
    return line


def export_name(recording: Path, file_format: str) -> str:
    return f"{recording.stem}.{file_format}"


@pytest.mark.parametrize("file_format", FORMATS)
@pytest.mark.slow
def test_export_never_overwrites_a_users_file(recording: Path, tmp_path: Path, file_format: str) -> None:
    target = tmp_path / export_name(recording, file_format)
    target.write_bytes(USERS)
    result = runner.invoke(app, ["export", str(recording), "--format", file_format, "--out", str(tmp_path)])
    assert result.exit_code == 2
    line = one_line(result.stderr)
    assert str(target) in line and "never writes over a file" in line
    assert snapshot(tmp_path) == {target.name: USERS}  # byte-identical, and nothing else written


def test_a_users_json_beside_the_csv_is_kept_and_nothing_is_written(recording: Path, tmp_path: Path) -> None:
    sidecar = tmp_path / f"{recording.stem}.json"
    sidecar.write_bytes(USERS)
    result = runner.invoke(app, ["export", str(recording), "--out", str(tmp_path)])
    assert result.exit_code == 2 and str(sidecar) in one_line(result.stderr)
    assert snapshot(tmp_path) == {sidecar.name: USERS}


@pytest.mark.slow
def test_a_symlink_at_the_target_is_not_followed(recording: Path, tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    users = elsewhere / "thesis.h5"
    users.write_bytes(USERS)
    out = tmp_path / "out"
    out.mkdir()
    (out / export_name(recording, "h5")).symlink_to(users)
    (out / export_name(recording, "mat")).symlink_to(elsewhere / "not-there-yet.mat")  # dangling
    for file_format in ("h5", "mat"):
        result = runner.invoke(app, ["export", str(recording), "--format", file_format, "--out", str(out)])
        assert result.exit_code == 2 and "symbolic link" in one_line(result.stderr)
    assert snapshot(elsewhere) == {"thesis.h5": USERS}  # the link's target untouched, none created
    assert all(path.is_symlink() for path in out.iterdir()) and len(list(out.iterdir())) == 2


@pytest.mark.slow
def test_two_recordings_of_one_name_into_one_folder_are_refused(recording: Path, tmp_path: Path) -> None:
    first, second = tmp_path / "monday" / "run.mcap", tmp_path / "tuesday" / "run.mcap"
    for copy in (first, second):
        copy.parent.mkdir()
        shutil.copyfile(recording, copy)
    out = tmp_path / "out"
    for args in ([first, second], [first, first]):
        result = runner.invoke(app, ["export", *map(str, args), "--format", "h5", "--out", str(out)])
        assert result.exit_code == 2
        line = one_line(result.stderr)
        assert str(second if args[1] == second else first) in line and "--out" in line
    assert not out.exists()  # refused before anything was written
    beside = runner.invoke(
        app, ["export", str(first), str(second), "--format", "h5"]
    )  # each into its own folder
    assert beside.exit_code == 0, beside.output
    written = [Path(line) for line in beside.stdout.splitlines()]
    assert [p.parent for p in written] == [first.parent, second.parent] and all(p.is_file() for p in written)


@pytest.mark.parametrize(("file_format", "users_name"), [("csv", "second.csv"), ("h5", "second_decay2.h5")])
@pytest.mark.slow
def test_a_taken_name_of_a_later_recording_stops_the_export_before_any_file(
    recording: Path, tmp_path: Path, file_format: str, users_name: str
) -> None:
    first, second = tmp_path / "first.mcap", tmp_path / "second.mcap"
    for copy in (first, second):
        shutil.copyfile(recording, copy)
    out = tmp_path / "out"
    out.mkdir()
    (out / users_name).write_bytes(USERS)
    result = runner.invoke(
        app, ["export", str(first), str(second), "--format", file_format, "--out", str(out)]
    )
    assert result.exit_code == 2 and users_name in one_line(result.stderr)
    assert snapshot(out) == {users_name: USERS}  # not even the first recording's export


@pytest.fixture
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A real 200 kB tmpfs: a disk that fills while an export is written (needs root to mount)."""
    mount = tmp_path / "full"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(mount)], capture_output=True
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.decode().strip() or 'not root'})")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=True)


def run_export(recording: Path, file_format: str, out: Path, limit_bytes: int | None = None):
    """``tankdaq export`` in a process of its own (a segfault would be its exit code, not this test's)."""

    def limit() -> None:  # the kernel's answer to a write past the limit: EFBIG, as a full disk's ENOSPC
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))  # type: ignore[arg-type]

    args = [TANKDAQ, "export", str(recording), "--format", file_format, "--out", str(out)]
    return subprocess.run(
        args, capture_output=True, text=True, timeout=120, preexec_fn=limit if limit_bytes else None
    )


@pytest.mark.parametrize("file_format", FORMATS)
@pytest.mark.slow
def test_a_full_disk_leaves_nothing_and_says_one_line(
    recording: Path, full_disk: Path, file_format: str
) -> None:
    users = full_disk / "notes.txt"
    users.write_bytes(USERS)
    (full_disk / "filler").write_bytes(bytes(120_000))  # what is left is less than any export of it
    result = run_export(recording, file_format, full_disk)
    assert result.returncode == 1, result.stderr
    line = one_line(result.stderr)
    assert "No space left on device" in line and export_name(recording, file_format) in line
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler", "notes.txt"]  # no partial, no temporary
    assert users.read_bytes() == USERS


@pytest.mark.parametrize("file_format", FORMATS)
@pytest.mark.slow
def test_a_write_the_kernel_refuses_leaves_nothing(recording: Path, tmp_path: Path, file_format: str) -> None:
    """Without root: the file size limit makes the kernel refuse the write part way (EFBIG)."""
    users = tmp_path / "notes.txt"
    users.write_bytes(USERS)
    result = run_export(recording, file_format, tmp_path, limit_bytes=20_000)
    assert result.returncode == 1, result.stderr
    assert "File too large" in one_line(result.stderr)
    assert snapshot(tmp_path) == {"notes.txt": USERS}


def test_an_injected_enospc_removes_the_temporary_file(tmp_path: Path) -> None:
    target = tmp_path / "table.csv"

    def fills_the_disk(out) -> None:
        out.write(b"time_s,roll_rad\n0.0,0.1\n")
        out.flush()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(RecordingError, match="No space left on device") as raised:
        write_new(target, fills_the_disk)
    assert raised.value.exit_code == 1 and "\n" not in str(raised.value)
    assert list(tmp_path.iterdir()) == []


def test_a_new_file_is_whole_under_its_name_and_refused_the_second_time(tmp_path: Path) -> None:
    target = tmp_path / "story.md"
    assert write_text_new(target, "# B\u0302_44, 5\u00b0\n") == target
    assert target.read_text(encoding="utf-8") == "# B\u0302_44, 5\u00b0\n"
    with pytest.raises(InputError, match="exists"):
        write_text_new(target, "other")
    assert (
        target.read_text(encoding="utf-8") == "# B\u0302_44, 5\u00b0\n" and len(list(tmp_path.iterdir())) == 1
    )


@pytest.mark.slow
def test_each_export_reads_back_with_its_standard_reader(recording: Path, tmp_path: Path) -> None:
    """Written through a temporary name and a hard link, every format is still the whole file."""
    for file_format in FORMATS:
        result = runner.invoke(
            app, ["export", str(recording), "--format", file_format, "--out", str(tmp_path)]
        )
        assert result.exit_code == 0, result.output
    csv = pd.read_csv(tmp_path / export_name(recording, "csv"))
    parquet = pd.read_parquet(tmp_path / export_name(recording, "parquet"))
    with h5py.File(tmp_path / export_name(recording, "h5"), "r") as h5:
        roll = h5["roll_rad"][:]
    assert csv["roll_rad"].tolist() == parquet["roll_rad"].tolist() == roll.tolist() and roll.size > 1000
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_campaign_report_never_overwrites_and_refuses_before_fitting(recording: Path, tmp_path: Path) -> None:
    report = tmp_path / "report"
    report.mkdir()
    (report / "campaign.csv").write_bytes(USERS)
    result = runner.invoke(app, ["campaign", str(recording), "--report", str(report)])
    assert result.exit_code == 2
    assert "campaign.csv" in one_line(result.stderr) and result.stdout == ""  # no fit was made
    assert snapshot(report) == {"campaign.csv": USERS}


@pytest.mark.slow
def test_a_report_figure_of_a_users_name_stops_the_report_before_any_file(
    recording: Path, tmp_path: Path
) -> None:
    report = tmp_path / "report"
    report.mkdir()
    figure = report / "b_eq_swath_roll.png"
    figure.write_bytes(USERS)
    result = runner.invoke(app, ["campaign", str(recording), "--report", str(report)])
    assert result.exit_code == 2 and str(figure) in error_line(result.stderr)  # known once the files are read
    assert snapshot(report) == {figure.name: USERS}


def test_diagnose_report_never_overwrites(recording: Path, tmp_path: Path) -> None:
    report = tmp_path / "report"
    report.mkdir()
    (report / "diagnose.md").write_bytes(USERS)
    result = runner.invoke(app, ["diagnose", str(recording), "--report", str(report)])
    assert result.exit_code == 2 and "diagnose.md" in one_line(result.stderr)
    assert snapshot(report) == {"diagnose.md": USERS}


@pytest.mark.slow
def test_a_report_onto_a_full_disk_leaves_only_whole_files(recording: Path, full_disk: Path) -> None:
    (full_disk / "filler").write_bytes(bytes(150_000))
    report = full_disk / "report"
    result = runner.invoke(app, ["campaign", str(recording), "--report", str(report)])
    assert result.exit_code == 1
    assert "No space left on device" in error_line(result.stderr)
    left = {path.name: path.read_bytes() for path in report.iterdir()}
    assert not [name for name in left if name.startswith(".")]  # no temporary file
    for name, data in left.items():  # what was written before the disk filled is whole
        if name.endswith(".png"):
            assert data.startswith(b"\x89PNG") and data.endswith(b"IEND\xaeB`\x82")
    if "campaign.csv" in left:
        assert len(pd.read_csv(report / "campaign.csv")) == 1


@pytest.mark.parametrize("command", [["export"], ["campaign"], ["diagnose"]])
def test_help_says_the_rule(command: list[str]) -> None:
    result = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0 and "never overwritten" in " ".join(result.stdout.split())
