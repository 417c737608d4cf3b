"""The reference integrator that makes known-truth decays: ODEPACK's LSODA against scipy's DOP853.

Both at the same tolerance (rtol 1e-10, atol 1e-12) on the decays tankdaq simulates (a 400 Hz minute
of a lightly damped hull, a 100 Hz nonlinear one, Coulomb friction), in the same run; the error of
each is against DOP853 at rtol 1e-13. Then a hidden-effect decay set (``make_decay_set``, three decays)
as the discrepancy tests draw it.

Run: .venv/bin/python bench/bench_reference_integrator.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import functools
import math
import statistics
import time
from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp

from benchjson import write_result
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.physics.decay import integrate_reference, terms_sum

#: (name, coefficients, Coulomb friction rad/s², output rate Hz, duration s, release angle rad)
CASES = (
    ("linear hull, 400 Hz, 60 s", {"b1": 0.1, "c1": 10.0}, 0.0, 400.0, 60.0, 0.15),
    (
        "quadratic damping, softening, 100 Hz, 40 s",
        {"b1": 0.05, "b2": 0.3, "c1": 4.0, "c3": -3.0},
        0.0,
        100,
        40,
        0.4,
    ),
    ("Coulomb friction, 100 Hz, 15 s", {"b1": 0.2, "c1": 9.0}, 0.02, 100.0, 15.0, 0.3),
)


def rhs_of(coefficients: dict[str, float], friction: float) -> Callable[[float, np.ndarray], list[float]]:
    total = terms_sum(coefficients)

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        x, v = float(y[0]), float(y[1])
        return [v, -total(x, v) - friction * math.tanh(v / 1e-3)]

    return rhs


def dop853(
    rhs: Callable[[float, np.ndarray], list[float]], t: np.ndarray, y0: list[float], rtol: float
) -> np.ndarray:
    sol = solve_ivp(rhs, (t[0], t[-1]), y0, t_eval=t, method="DOP853", rtol=rtol, atol=rtol / 100)
    return sol.y[0]


def timed(work: Callable[[], np.ndarray], repeats: int) -> tuple[float, np.ndarray]:
    """Median CPU seconds of ``work`` and its last result."""
    times = []
    for _ in range(repeats):
        start = time.process_time()
        result = work()
        times.append(time.process_time() - start)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print("| decay | DOP853 CPU ms | its error rad | LSODA CPU ms | its error rad | DOP853 / LSODA |")
    print("|---|---:|---:|---:|---:|---:|")
    figures: dict[str, object] = {}
    for name, coefficients, friction, rate_hz, duration_s, angle0 in CASES:
        t = np.arange(round(rate_hz * duration_s)) / rate_hz
        rhs = rhs_of(coefficients, friction)
        truth = dop853(rhs, t, [angle0, 0.0], 1e-13)
        old, old_angle = timed(functools.partial(dop853, rhs, t, [angle0, 0.0], 1e-10), args.repeats)
        new, new_states = timed(functools.partial(integrate_reference, rhs, t, [angle0, 0.0]), args.repeats)
        print(
            f"| {name} | {old * 1e3:.1f} | {np.abs(old_angle - truth).max():.1e} | {new * 1e3:.1f} | "
            f"{np.abs(new_states[:, 0] - truth).max():.1e} | {old / new:.1f}× |"
        )
        figures[name] = {
            "dop853_cpu_ms": old * 1e3,
            "dop853_error_rad": np.abs(old_angle - truth).max(),
            "lsoda_cpu_ms": new * 1e3,
            "lsoda_error_rad": np.abs(new_states[:, 0] - truth).max(),
        }
    seconds, _ = timed(lambda: np.array(len(make_decay_set(["friction.coulomb"], seed=1).runs)), args.repeats)
    print(f"\na hidden-effect set (Coulomb friction, three decays): {seconds * 1e3:.0f} ms CPU")
    figures["hidden_effect_set_coulomb_cpu_ms"] = seconds * 1e3
    write_result(
        "reference_integrator",
        "the reference integrator (ODEPACK LSODA) against scipy's DOP853 at the same tolerance on tankdaq's "
        "decays (CPU, error against DOP853 at rtol 1e-13), and one hidden-effect decay set",
        counts={"repeats": args.repeats, "cases": len(CASES)},
        figures=figures,
        ratios={
            name: {"dop853_over_lsoda_cpu": f["dop853_cpu_ms"] / f["lsoda_cpu_ms"]}  # type: ignore[index]
            for name, f in figures.items()
            if isinstance(f, dict)
        },
        baseline="scipy's DOP853 at the same tolerance, same run",
    )


if __name__ == "__main__":
    main()
