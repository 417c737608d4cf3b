"""Draws the report figures the docs show, into docs/img/ (the same file names), from what a user runs.

- ``demo-decay-fit.png``: a decay of ``tankdaq demo`` (the simulated MTi-G), its joint fit and residual;
- ``diagnose-simulation.png``: the docs/diagnose.md example, a potential-flow-like simulation of KVLCC2
  run 21338 (its restoring, a third of its linear damping, no viscous damping; 50 Hz, degrees) against
  the measurement, with the shipped ``kvlcc2`` hull;
- ``diagnose-models.png``, ``diagnose-spectrum.png``: ``tankdaq diagnose --report`` of run 21338.

Run: ``.venv/bin/python bench/docs_figures.py`` (needs ``../shared/data``; about a minute).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
KVLCC2 = ROOT.parent / "shared" / "data" / "kvlcc2-roll-decay" / "model_test_21338.csv"
TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))
READ = ["--time-col", "time", "--angle-col", "phi", "--angle-unit", "rad"]


def run(*args: str) -> None:
    subprocess.run([TANKDAQ, *args], check=True, stdout=subprocess.DEVNULL)


def demo_figure(work: Path) -> None:
    run("demo", "--out", str(work / "demo"), "--runs", "1", "--sim-speed", "10")
    (png,) = (work / "demo").glob("*.png")
    shutil.copyfile(png, IMG / "demo-decay-fit.png")


def potential_flow_csv(path: Path) -> Path:
    """The docs' simulation: the measurement's own fit with a third of its b1 and no viscous damping,
    simulated at 50 Hz from the measured release and written in degrees (``t_sim,roll_deg``)."""
    from tankdaq.diagnose.compare import best_damping_form
    from tankdaq.ident.free_decay import cut_free_decays
    from tankdaq.ident.inputs import read_decays
    from tankdaq.physics.decay import simulate_decay

    runs = cut_free_decays(read_decays(KVLCC2, "roll", "time", "phi", None, "rad"), None, None)
    fit = best_damping_form(runs)
    c = fit.coefficients_
    t = np.arange(0.0, 120.0, 0.02)
    angle0, rate0 = fit.initial_states_[0]
    angle = simulate_decay({"b1": c["b1"] / 3, "c1": c["c1"], "c3": c["c3"]}, t, angle0, rate0)[0]
    rows = np.column_stack([t, np.degrees(angle)])
    np.savetxt(path, rows, delimiter=",", header="t_sim,roll_deg", comments="", fmt="%.10g")
    return path


def diagnose_figures(work: Path) -> None:
    sim = potential_flow_csv(work / "potential.csv")
    sim_read = ["--sim-time-col", "t_sim", "--sim-angle-col", "roll_deg", "--sim-angle-unit", "deg"]
    run("diagnose", str(KVLCC2), *READ, "--simulation", str(sim), *sim_read, "--hull", "kvlcc2",
        "--report", str(work / "sim"))  # fmt: skip
    shutil.copyfile(work / "sim" / "simulation.png", IMG / "diagnose-simulation.png")
    shutil.copyfile(work / "sim" / "damping.png", IMG / "diagnose-damping.png")
    run("diagnose", str(KVLCC2), *READ, "--report", str(work / "diag"))
    shutil.copyfile(work / "diag" / "models.png", IMG / "diagnose-models.png")
    shutil.copyfile(work / "diag" / "spectrum.png", IMG / "diagnose-spectrum.png")


def main() -> None:
    if not KVLCC2.is_file():
        sys.exit(f"the KVLCC2 data is not at {KVLCC2}")
    with tempfile.TemporaryDirectory() as folder:
        demo_figure(Path(folder))
        diagnose_figures(Path(folder))
    print(f"figures written to {IMG}")


if __name__ == "__main__":
    main()
