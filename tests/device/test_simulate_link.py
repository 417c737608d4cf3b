"""``simulate --link PATH`` never replaces or deletes what is not its own link (issue 19).

It used to put its symlink over an existing regular file and delete it on exit. Now anything at the
path but a dead simulator's link (to a /dev/pts entry that is gone) is refused in one line, exit 2,
the file untouched; on exit only the link it made, still pointing at its pty, is removed. Real
``tankdaq simulate`` processes, stopped by the test.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))
STOP_S = 30.0


def _simulate(link: Path) -> subprocess.Popen[str]:
    args = [TANKDAQ, "simulate", "--link", str(link), "--runs", "0"]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("kind", ["file", "link to a file"])
@pytest.mark.slow
def test_link_over_something_not_its_own_is_refused_and_left_untouched(tmp_path: Path, kind: str) -> None:
    precious = tmp_path / "notes.txt"
    precious.write_text("calibration of the tank, day 3\n")
    target = precious
    if kind == "link to a file":
        target = tmp_path / "ttyUSB-notes"
        target.symlink_to(precious)
    done = subprocess.run(
        [TANKDAQ, "simulate", "--link", str(target)], capture_output=True, text=True, timeout=STOP_S
    )
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --link "), done.stderr
    assert "Traceback" not in done.stderr and done.stdout == ""
    assert precious.read_text() == "calibration of the tank, day 3\n"
    assert target.is_symlink() == (kind == "link to a file")


@pytest.mark.slow
def test_a_dead_simulators_link_is_reused_and_only_its_own_link_is_removed_on_exit(tmp_path: Path) -> None:
    link = tmp_path / "ttyMTi"
    gone = "/dev/pts/999999"
    assert not os.path.exists(gone)
    link.symlink_to(gone)  # left by a simulator killed with -9
    proc = _simulate(link)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == str(link)
        pty = os.readlink(link)
        assert pty.startswith("/dev/pts/") and os.path.exists(pty)
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=STOP_S)
    assert proc.returncode == 0, err
    assert not os.path.lexists(link), "its own link is removed on exit"


@pytest.mark.slow
def test_a_file_put_where_the_link_was_survives_the_simulators_exit(tmp_path: Path) -> None:
    link = tmp_path / "ttyMTi"
    proc = _simulate(link)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == str(link)
        link.unlink()
        link.write_text("someone's file\n")  # the path now holds something the simulator did not make
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=STOP_S)
    assert proc.returncode == 0, err
    assert link.read_text() == "someone's file\n"
