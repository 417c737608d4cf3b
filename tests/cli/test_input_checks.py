"""Everything the command line can check is checked first: one line, exit 2, nothing started, no traceback.

The probe of issue 11 found path errors that gave tracebacks (or exit 1) and values that were
accepted silently; each is a case here. A case that would need a device must be refused before
the simulator starts: the test gives tempfile a private folder and checks that no simulator
folder (``tankdaq-sim-*``) and no recording appeared in it or in the output folder.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from support.held_tilt import write_held_tilt_csv
from tankdaq.cli import app
from tankdaq.config import validation
from tankdaq.errors import InputError

runner = CliRunner()

#: A path no one can create a file in, even root: /proc refuses new entries.
UNWRITABLE = "/proc/tankdaq-probe/x"

RECORD = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8", "--viewer", "none"]
RECORD += ["--runs", "1"]  # should a case not be refused, it ends after one decay instead of never


@pytest.fixture
def places(tmp_path: Path, private_tempdir: Path) -> dict[str, Path]:
    """A private temporary folder (where a simulator would put its pty link), a CSV decay, a file."""
    a_file = tmp_path / "a-file"
    a_file.write_text("not a folder")
    return {
        "tmp": private_tempdir,
        "out": tmp_path / "out",
        "csv": write_held_tilt_csv(tmp_path / "decay.csv"),
        "file": a_file,
        "dir": tmp_path,
    }


def _refused(args: list[str], mentions: str) -> str:
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert mentions in lines[0], lines[0]
    return lines[0]


def _nothing_started(places: dict[str, Path]) -> None:
    assert not list(places["tmp"].iterdir()), "a simulator (or something else) was started"
    assert not places["out"].exists(), "a refused command left a folder (or a recording) behind"


DEVICE_CASES = [
    ([*RECORD, "--out", UNWRITABLE], "--out"),
    ([*RECORD, "--out", "{file}"], "is a file, not a folder"),
    (["demo", "--out", UNWRITABLE], "--out"),
    (["demo", "--out", "{file}"], "is a file, not a folder"),
    ([*RECORD, "--out", "{out}", "--model", "b1,c1,ku"], "ku needs a measured input u(t)"),
    ([*RECORD, "--out", "{out}", "--baud", "0"], "--baud 0 is not an MTi baud rate"),
    ([*RECORD, "--out", "{out}", "--rate", "0.5"], "--rate 0.5 Hz is not an MTi output rate"),
    ([*RECORD, "--out", "{out}", "--viewer", "rerun+http://[::1"], "(Invalid IPv6 URL)"),  # recorded before
    ([*RECORD, "--out", "{out}", "--viewer", "rerun+http://127.0.0.1:99999/proxy"], "Port out of range"),
    ([*RECORD, "--out", "{out}", "--viewer", "rerun+http:///proxy"], "names no host"),
    (["simulate", "--rate", "1000"], "--rate 1000 Hz is not an MTi output rate"),
    (["simulate", "--angle", "-5"], "--angle -5 is not a release angle"),
    (["simulate", "--draft", "2T"], "outside the configured drafts"),
    (["simulate", "--baud", "0"], "--baud 0"),
    (["simulate", "--link", UNWRITABLE], "--link"),
    (["simulate", "--link", "{dir}"], "is a folder"),
]

WORK_CASES = [
    (["campaign", "{dir}", "--report", UNWRITABLE], "--report"),
    (["campaign", "{dir}", "--report", "{file}"], "is a file, not a folder"),
    (["simulate-campaign", UNWRITABLE], "FOLDER"),
    (["simulate-campaign", "{out}", "--angle", "90"], "--angle 90 is not a release angle"),
    (["simulate-campaign", "{out}", "--draft", "2T"], "outside the configured drafts"),
    (["auv", "simulate", "--out", UNWRITABLE + ".mcap"], "does not exist"),
    (["auv", "simulate", "--out", "/proc/x.mcap"], "cannot write"),
    (["auv", "validate", "{csv}", "--plot", UNWRITABLE + ".png"], "--plot"),
    (["auv", "sensitivity", "--step", "150"], "--step 150 %"),
    (["recover", "{csv}", "-o", UNWRITABLE + ".mcap"], "--out"),
    (["diagnose", "{csv}", "--report", UNWRITABLE], "--report"),
    (["diagnose", "{csv}", "--rrd", UNWRITABLE + ".rrd"], "--rrd"),
    (["identify", "{csv}", "--hull", "swath", "--draft", "2T"], "outside the configured drafts"),
    (["identify", "{csv}", "--bootstrap", "100000000"], "up to 10000"),
    (["identify", "{dir}"], "is a folder, not a file"),
    (["diagnose", "{dir}"], "is a folder, not a file"),
    (["replay", "{dir}"], "is a folder, not a file"),
    (["recover", "{dir}"], "is a folder, not a recording"),
    (["auv", "identify", "{dir}"], "is a folder, not a file"),
]


@pytest.mark.parametrize(("args", "mentions"), DEVICE_CASES + WORK_CASES)
@pytest.mark.slow
def test_refused_in_one_line_before_a_device_opens_or_work_starts(
    places: dict[str, Path], args: list[str], mentions: str
) -> None:
    _refused([a.format(**places) for a in args], mentions)
    _nothing_started(places)


def test_checking_an_output_folder_leaves_nothing_behind(tmp_path: Path) -> None:
    folder = tmp_path / "a" / "b"
    assert validation.output_dir(folder) == folder and list(tmp_path.iterdir()) == []
    folder.mkdir(parents=True)
    assert validation.output_dir(folder) == folder and list(folder.iterdir()) == []  # the probe file is gone


@pytest.mark.parametrize("rate", [1, 2, 5, 25, 50, 100, 200, 400])
def test_every_whole_divisor_of_400_hz_is_an_output_rate(rate: int) -> None:
    assert validation.output_rate_hz(float(rate)) == rate


@pytest.mark.parametrize("rate", [0.0, 0.5, 3.0, 150.0, 800.0, 1000.0, float("nan")])
def test_other_rates_are_refused(rate: float) -> None:
    with pytest.raises(InputError, match="divisor of 400"):
        validation.output_rate_hz(rate)


def test_the_record_daemon_applies_the_same_rules_as_the_command_line(
    tmp_path: Path, record_settings
) -> None:
    from tankdaq.acquire.daemon import RecordDaemon

    for bad, match in (
        ({"rate_hz": 0.5}, "output rate"),
        ({"baud": 0}, "baud rate"),
        ({"angle_deg": 60.0}, "release angle"),
        ({"model": "b1,c1,ku"}, "ku needs a measured input"),
        ({"out_dir": tmp_path / "a-file"}, "not a folder"),
    ):
        (tmp_path / "a-file").write_text("")
        with pytest.raises(InputError, match=match):
            RecordDaemon(record_settings(**bad))


@pytest.mark.parametrize(
    ("args", "mentions"),
    [
        (["record", "--hull", "swath", "--draft", "T", "--angle", "8"], "Missing option '--port'"),
        ([*RECORD, "--scan-bauds"], "No such option"),
        (["identify", "x.csv", "--skip-half-cycles", "-1"], "--skip-half-cycles"),
        (["decode", "x.bin", "--format", "xml"], "--format"),
        (["nosuch"], "No such command"),
    ],
)
@pytest.mark.slow
def test_click_usage_errors_are_one_line_too(args: list[str], mentions: str) -> None:
    line = _refused(args, mentions)
    assert "--help lists the options" in line


def test_no_arguments_still_shows_the_help() -> None:
    result = runner.invoke(app, [])
    assert "Commands" in result.output and "record" in result.output and "Traceback" not in result.output
