"""The live view in a process of its own (``viz.view_process.ViewProcess``): every .rrd whole (read back
with rerun's reader) across the processes that replace each other, a view process that dies costs a
note and never the caller, and every process started is stopped."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from support.rrd_checks import read_rrd
from tankdaq.physics.decay import simulate_decay
from tankdaq.samples import empty_samples
from tankdaq.viz.view_process import ViewProcess

TRUTH = {"b1": 0.3, "c1": 40.0}
SAMPLES = 300


def decay_samples(origin_s: float) -> np.ndarray:
    samples = empty_samples(SAMPLES)
    samples["t"] = origin_s + np.arange(SAMPLES) / 100.0
    samples["roll"], samples["p"] = simulate_decay(TRUTH, samples["t"], np.radians(6.0))
    return samples


def show_run(view: ViewProcess, path: Path, run: int) -> None:
    """One decay as the view sink shows it: a run, its samples in blocks, a fit, its end."""
    samples = decay_samples(10.0 * run)
    view.new_run(f"run {run}", rrd_path=path, terms=list(TRUTH), time_origin_s=float(samples["t"][0]))
    view.log_event("release", f"run {run} released", float(samples["t"][0]))
    for start in range(0, SAMPLES, 50):
        view.log_samples(samples[start : start + 50])
    view.log_fit(samples["t"], samples["roll"], samples["p"], TRUTH, t_fit=float(samples["t"][-1]))
    view.end_run()


@pytest.mark.slow
def test_runs_go_to_fresh_processes_and_every_rrd_is_whole(tmp_path: Path) -> None:
    notes: list[str] = []
    view = ViewProcess("save", terms=list(TRUTH), on_note=notes.append, runs_per_process=2)
    try:
        for run in range(1, 6):
            show_run(view, tmp_path / f"run{run}.rrd", run)
    finally:
        view.close()
    assert view.processes_started == 3  # runs 1-2, 3-4, 5 (each replaced after its second run)
    for run in range(1, 6):
        scalars, texts = read_rrd(tmp_path / f"run{run}.rrd")
        assert len(scalars["/angle/measured"]) == SAMPLES
        assert texts == [f"release: run {run} released"]
    assert view.dropped == 0 and notes == []


@pytest.mark.slow
def test_a_view_process_killed_costs_a_note_and_the_next_run_gets_another(tmp_path: Path) -> None:
    noted = threading.Event()
    notes: list[str] = []

    def on_note(line: str) -> None:
        notes.append(line)
        noted.set()

    view = ViewProcess("save", terms=list(TRUTH), on_note=on_note)
    try:
        show_run(view, tmp_path / "run1.rrd", 1)
        assert view.wait_idle(60.0)
        os.kill(view.pids[-1], signal.SIGKILL)
        for _ in range(200):  # each send into the dead process's pipe until it is seen gone
            view.log_event("note", "after the kill")
            if noted.wait(0.05):
                break
        assert notes and notes[0].startswith("the view process ended (exit -9)")
        show_run(view, tmp_path / "run2.rrd", 2)
    finally:
        view.close()
    assert view.processes_started == 2
    scalars, _ = read_rrd(tmp_path / "run2.rrd")
    assert len(scalars["/angle/measured"]) == SAMPLES


@pytest.mark.slow
def test_closing_leaves_no_view_process(tmp_path: Path) -> None:
    view = ViewProcess("save", terms=list(TRUTH), runs_per_process=1)
    show_run(view, tmp_path / "run1.rrd", 1)
    show_run(view, tmp_path / "run2.rrd", 2)
    assert view.wait_idle(60.0)
    pids = view.pids  # the one after run 2 and those before it not yet reaped
    view.close()
    assert view.processes_started == 3 and pids and view.pids == []
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)  # joined: not even a zombie is left


@pytest.mark.slow
def test_a_script_without_a_main_guard_is_not_run_again_by_the_view(tmp_path: Path) -> None:
    """A lab's own script that records with the view, written without ``if __name__ == "__main__"``:
    the view's process must not import it again (it would record twice, or fail starting)."""
    marker = tmp_path / "imports.txt"
    script = tmp_path / "lab_script.py"
    script.write_text(
        "from pathlib import Path\n"
        "import numpy as np\n"
        "from tankdaq.samples import empty_samples\n"
        "from tankdaq.viz.view_process import ViewProcess\n"
        f"with open({str(marker)!r}, 'a') as fh:\n"
        "    fh.write('imported\\n')\n"
        "view = ViewProcess('save')\n"
        f"view.new_run('run', rrd_path=Path({str(tmp_path / 'script.rrd')!r}))\n"
        "samples = empty_samples(50)\n"
        "samples['t'] = np.arange(50) / 100.0\n"
        "view.log_samples(samples)\n"
        "view.close()\n"
    )
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert marker.read_text() == "imported\n"
    scalars, _ = read_rrd(tmp_path / "script.rrd")
    assert len(scalars["/angle/measured"]) == 50
