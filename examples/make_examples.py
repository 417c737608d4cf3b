"""Write the small example files the docs' commands read (run once; the files are committed).

Every file is made here from the decay equation or tankdaq's own simulator, never copied from a lab's data:

- ``kvlcc2_roll_decay.csv``: another lab's CSV of a KVLCC2 model's roll decay (1:68), columns ``time`` (s)
  and ``phi`` (rad), from the release on, 20 Hz with 0.01 deg of noise.
- ``kvlcc2_roll_decay.h5``: the same decay in HDF5 as a lab's run database keeps it (``run/time``,
  ``run/phi``).
- ``kvlcc2_potential.csv``: the lab's potential-flow simulation of that decay, ``t_sim`` (s) and
  ``roll_deg``: linear damping only (what potential flow leaves out is what diagnose finds).
- ``capture.bin``: 6 kB of raw serial bytes of the simulated MTi-G (what ``tankdaq decode`` reads).

``python examples/make_examples.py`` writes them again (the same bytes: fixed seeds).
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import h5py
import numpy as np
from scipy.integrate import solve_ivp

HERE = Path(__file__).resolve().parent
#: KVLCC2 at 1:68: period 2.55 s; quadratic damping the potential flow misses (docs/diagnose.md).
MEASURED = {"b1": 0.02, "b2": 0.12, "c1": 6.065, "c3": 3.94}
POTENTIAL = {"b1": 0.00628, "b2": 0.0, "c1": 6.065, "c3": 3.944}


def decay(coefficients: dict[str, float], rate_hz: float, duration_s: float, phi0_deg: float) -> np.ndarray:
    """(t, phi rad) of x'' + b1 x' + b2 |x'| x' + c1 x + c3 x^3 = 0 released at rest from ``phi0_deg``."""
    b1, b2, c1, c3 = (coefficients[k] for k in ("b1", "b2", "c1", "c3"))

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        x, v = y
        return [v, -(b1 * v + b2 * abs(v) * v + c1 * x + c3 * x**3)]

    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    y0 = [np.radians(phi0_deg), 0.0]
    solved = solve_ivp(rhs, (0.0, duration_s), y0, t_eval=t, rtol=1e-10, atol=1e-12, method="DOP853")
    return np.column_stack([t, solved.y[0]])


def main() -> None:
    noise = np.random.default_rng(21338)
    measured = decay(MEASURED, 20.0, 30.0, 10.4)
    measured[:, 1] += np.radians(0.01) * noise.standard_normal(len(measured))
    np.savetxt(HERE / "kvlcc2_roll_decay.csv", measured, fmt="%.2f,%.6f", header="time,phi", comments="")
    with h5py.File(HERE / "kvlcc2_roll_decay.h5", "w") as h5:
        h5["run/time"] = measured[:, 0]
        h5["run/phi"] = measured[:, 1]
        h5["run/phi"].attrs["unit"] = "rad"
        h5["run/time"].attrs["unit"] = "s"
    potential = decay(POTENTIAL, 10.0, 30.0, 10.25)
    potential[:, 1] = np.degrees(potential[:, 1])
    np.savetxt(
        HERE / "kvlcc2_potential.csv", potential, fmt="%.1f,%.4f", header="t_sim,roll_deg", comments=""
    )
    _capture(HERE / "capture.bin", 6000)


def _capture(path: Path, size: int) -> None:
    """The first chunks (about ``size`` bytes) of serial bytes of a simulated decay test (``tankdaq
    record --port sim`` keeps them in its recording), as a serial capture holds them."""
    from tankdaq.store.reader import iter_raw_chunks

    with tempfile.TemporaryDirectory() as folder:
        record = ["tankdaq", "record", "--port", "sim", "--draft", "T", "--angle", "8", "--hull", "swath"]
        quick = ["--runs", "1", "--seed", "1", "--sim-speed", "20", "--viewer", "none", "--catalogue", "none"]
        subprocess.run([*record, *quick, "--out", folder], check=True, capture_output=True)
        (recording,) = Path(folder).glob("*.mcap")
        data = bytearray()
        for _, chunk in iter_raw_chunks(recording):
            data += chunk
            if len(data) >= size:
                break
    path.write_bytes(bytes(data))


if __name__ == "__main__":
    main()
