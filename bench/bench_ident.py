"""Identification benchmarks: fit time, online refit time, Monte Carlo efficiency vs the Cramer-Rao bound.

Run as ``.venv/bin/python bench/bench_ident.py [fit] [--runs 200]``
(pinned to one core, BLAS single-threaded). Times are
CPU time of this process (what one core spends; the shared machine's load inflates wall time) with the
wall time beside it.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import math
import statistics
import time

import numpy as np

from benchjson import write_result
from tankdaq.ident.derived import b_eq
from tankdaq.ident.equation_error import EquationErrorFit
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.live.identifier import OnlineIdentifier
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

ANGLE_NOISE = 1e-3  # rad
RATE_NOISE = 5e-3  # rad/s
TRUTH = {"b1": 0.3, "b2": 0.4, "b3": 0.5, "c1": 14.0, "c2": 0.8, "c3": 60.0}


def decay(coefficients: dict[str, float], seed: int, n: int = 1500, angle0: float = 0.3) -> DecayRun:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    angle, rate = simulate_decay(coefficients, t, angle0)
    return DecayRun(
        t=t, angle=angle + 0.01 + rng.normal(0, ANGLE_NOISE, n), rate=rate + rng.normal(0, RATE_NOISE, n)
    )


def bench_fit_time(repeats: int = 40) -> dict[str, float]:
    """Median time of one fit by output error and by equation error: 1500 samples, 7 terms (seed001-eq1 +
    Coulomb friction)."""
    terms = ("b1", "b2", "b3", "c1", "c2", "c3", "fc")
    run = decay(TRUTH, seed=1)
    figures = {}
    for method, estimator in (("oe", OutputErrorFit), ("ee", EquationErrorFit)):
        estimator(terms).fit([run])  # JIT warm-up (compiled code is cached on disk too)
        cpu, wall = [], []
        for _ in range(repeats):
            cpu0, wall0 = time.process_time(), time.perf_counter()
            estimator(terms).fit([run])
            cpu.append(time.process_time() - cpu0)
            wall.append(time.perf_counter() - wall0)
        print(
            f"fit, 1500 samples, 7 terms, {method}: median {1e3 * statistics.median(cpu):.1f} ms CPU "
            f"({1e3 * statistics.median(wall):.1f} ms wall) over {repeats} fits"
        )
        figures[f"{method}_ms_cpu"] = 1e3 * statistics.median(cpu)
        figures[f"{method}_ms_wall"] = 1e3 * statistics.median(wall)
    return figures


def bench_online(packet: int = 10) -> dict[str, float]:
    """Online refits over a 15 s, 100 Hz decay fed in 10-sample packets (CPU time per refit)."""
    run = decay({k: TRUTH[k] for k in ("b1", "b2", "c1", "c3")}, seed=2)
    OnlineIdentifier("b1,b2,c1,c3").update(run.t, run.angle, run.rate)  # warm-up
    online = OnlineIdentifier("b1,b2,c1,c3")
    refits = []
    for start in range(0, run.t.size, packet):
        sl = slice(start, start + packet)
        cpu0 = time.process_time()
        if online.update(run.t[sl], run.angle[sl], run.rate[sl]) is not None:
            refits.append(1e3 * (time.process_time() - cpu0))
    print(
        f"online: {len(refits)} refits, median {statistics.median(refits):.1f} ms CPU, "
        f"max {max(refits):.1f} ms; "
        f"the last ones on ~15 s of 100 Hz data: {', '.join(f'{r:.1f}' for r in refits[-3:])} ms"
    )
    return {
        "refits": len(refits),
        "median_ms_cpu": statistics.median(refits),
        "max_ms_cpu": max(refits),
        "last_ms_cpu": refits[-1],
    }


def bench_cramer_rao(n_runs: int = 200, amplitude_deg: float = 10.0) -> dict[str, float]:
    """RMSE of b1, c1 and B_eq(amplitude) over white-noise Monte Carlo runs, divided by the Cramer-Rao bound.

    The bound is (J'J)^-1 of the noise-weighted exact Jacobian at the truth, nuisance parameters (initial
    state, offset) included; B_eq's bound by the delta method.
    """
    terms = ("b1", "b2", "c1", "c3")
    truth = {k: TRUTH[k] for k in terms}
    reference = OutputErrorFit(terms).fit([decay(truth, seed=0)])
    p_true = reference.params_.copy()
    p_true[: len(terms)] = [truth[k] for k in terms]
    p_true[len(terms) :] = [0.3, 0.0, 0.01]
    reference._model.sigmas = [{"angle": ANGLE_NOISE, "rate": RATE_NOISE}]
    _, jac, _, _ = reference._model.weighted(p_true)
    crb = np.linalg.inv(jac.T @ jac)[: len(terms), : len(terms)]
    amplitude = math.radians(amplitude_deg)
    grad = np.array(
        [
            (b_eq({**truth, k: truth[k] + 1e-6}, amplitude) - b_eq({**truth, k: truth[k] - 1e-6}, amplitude))
            / 2e-6
            for k in terms
        ]
    )
    bounds = {"b1": math.sqrt(crb[0, 0]), "c1": math.sqrt(crb[2, 2]), "B_eq": math.sqrt(grad @ crb @ grad)}
    errors: dict[str, list[float]] = {name: [] for name in bounds}
    for seed in range(1, n_runs + 1):
        fit = OutputErrorFit(terms, compute_diagnostics=False).fit([decay(truth, seed=1000 + seed)])
        errors["b1"].append(fit.coefficients_["b1"] - truth["b1"])
        errors["c1"].append(fit.coefficients_["c1"] - truth["c1"])
        errors["B_eq"].append(b_eq(fit.coefficients_, amplitude) - b_eq(truth, amplitude))
    ratios = {}
    for name, bound in bounds.items():
        rmse = math.sqrt(float(np.mean(np.square(errors[name]))))
        print(
            f"Cramer-Rao, {name}{f' at {amplitude_deg:g} deg' if name == 'B_eq' else ''}: RMSE {rmse:.3g}, "
            f"bound {bound:.3g}, ratio {rmse / bound:.3f} ({n_runs} runs)"
        )
        ratios[f"{name}_rmse_over_cramer_rao"] = rmse / bound
    return ratios


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", nargs="?", choices=("fit",), help="the fit time alone")
    parser.add_argument("--runs", type=int, default=200, help="Monte Carlo runs against the Cramer-Rao bound")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    figures: dict[str, dict[str, float]] = {"fit_1500_samples_7_terms": bench_fit_time()}
    if args.part != "fit":
        figures["online_refit_15s_100hz"] = bench_online()
        figures["cramer_rao"] = bench_cramer_rao(args.runs)
    write_result(
        "ident",
        "fit time of one decay (output error, equation error; CPU of one pinned core), the live identifier's "
        "refits over a 15 s decay, and Monte Carlo RMSE over the Cramer-Rao bound",
        counts={"fit_repeats": 40, "cramer_rao_runs": 0 if args.part else args.runs},
        figures=figures,
    )


if __name__ == "__main__":
    main()
