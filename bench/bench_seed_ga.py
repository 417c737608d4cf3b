"""The seeds' GA and PSO: tankdaq's numpy search against pymoo's, and against output error.

One known-truth decay: the SWATH roll model at design draft (seed 001 eq. 8, configs/hulls/swath.toml),
released from 5 deg, 15 s at 100 Hz (seed 001 kept the first 15 s), white noise 1e-3 rad on the angle
and 0.01 rad/s on the gyro -- the gyro level that makes the truth's seed objective match the seeds'
printed values (0.0128 rad/s at T, 5 deg).

1. The search alone (``ident/population_search.py``) on the seeds' objective with seed 000's GA preset
   (200 x 2000) and seed 001's PSO preset (200 x 1000), and, where pymoo is importable, pymoo's GA (SBX,
   PM) and adaptive PSO -- what ``GeneticSeedFit``/``SwarmSeedFit`` ran on before -- on the same objective,
   box, settings and seed in the same run: CPU seconds of each, the ratio, the best objective each reached.
   The objective's own CPU for as many evaluations says how much of pymoo's time was its bookkeeping.
2. The fits (``GeneticSeedFit``, ``SwarmSeedFit``) against output error: objectives, R2 of the angle,
   B_eq at 5 deg and T0 against the truth.

    .venv/bin/python bench/bench_seed_ga.py [--generations N]   (N scales both presets down; a few minutes
                                                                  at the papers' sizes with pymoo installed)

Writes bench/results/seed_search.json.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time
from collections.abc import Callable
from dataclasses import replace
from typing import TypeVar

import numpy as np

from benchjson import write_result
from tankdaq.config.hulls import load_hull
from tankdaq.ident.derived import b_eq, natural_period
from tankdaq.ident.evolutionary import (
    GENETIC_SETTINGS,
    SWARM_SETTINGS,
    GeneticSeedFit,
    GeneticSettings,
    OneStepData,
    SearchSpace,
    SwarmSeedFit,
    SwarmSettings,
)
from tankdaq.ident.one_step import seed_objective
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.ident.population_search import Objective
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

T = TypeVar("T")
MODEL = "seed001-eq1"
OE_REPEATS = 20
SEED = 0


def noisy_decay(truth: dict[str, float]) -> DecayRun:
    t = np.arange(0.0, 15.0, 0.01)
    angle, rate = simulate_decay(truth, t, np.deg2rad(5.0))
    rng = np.random.default_rng(2026)
    return DecayRun(
        t, angle + rng.normal(0, 1e-3, t.size), rate + rng.normal(0, 0.01, t.size), name="swath-T-5deg"
    )


def cpu_s(work: Callable[[], T]) -> tuple[float, T]:
    """CPU seconds (this process, user + system) of one call, and what it returned."""
    started = time.process_time()
    out = work()
    return time.process_time() - started, out


def ours(objective: Objective, space: SearchSpace, settings: GeneticSettings | SwarmSettings) -> float:
    """Best objective of tankdaq's search, as GeneticSeedFit/SwarmSeedFit run it."""
    return settings.search(objective, space.lower, space.upper, np.random.default_rng(SEED)).objective


def pymoo_search(
    objective: Objective, space: SearchSpace, settings: GeneticSettings | SwarmSettings
) -> float:
    """Best objective of pymoo's GA or adaptive PSO, configured as tankdaq's estimators did before."""
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.algorithms.soo.nonconvex.pso import PSO
    from pymoo.core.problem import Problem
    from pymoo.operators.crossover.sbx import SBX
    from pymoo.operators.mutation.pm import PM
    from pymoo.optimize import minimize

    class OneStepProblem(Problem):
        def __init__(self) -> None:
            super().__init__(n_var=space.lower.size, n_obj=1, xl=space.lower, xu=space.upper)

        def _evaluate(self, x: np.ndarray, out: dict, *args: object, **kwargs: object) -> None:
            out["F"] = objective(x)[:, None]

    if isinstance(settings, GeneticSettings):
        algorithm = GA(
            pop_size=settings.population,
            crossover=SBX(prob=settings.crossover),
            mutation=PM(prob=settings.mutation),
            eliminate_duplicates=False,
        )
    else:
        algorithm = PSO(pop_size=settings.population, max_velocity_rate=settings.max_velocity, adaptive=True)
    result = minimize(
        OneStepProblem(), algorithm, termination=("n_gen", settings.generations), seed=SEED, verbose=False
    )
    return float(np.min(result.F))


def searches(run: DecayRun, generations: int | None) -> tuple[dict[str, object], dict[str, float]]:
    """CPU and best objective of each search, ours and pymoo's; ratios pymoo / ours."""
    space = SearchSpace.for_model(MODEL)
    data = OneStepData.from_runs([run], space.terms)

    def objective(x: np.ndarray) -> np.ndarray:
        return data.rms(space.coefficients(x))

    presets: dict[str, GeneticSettings | SwarmSettings] = {
        "ga": GENETIC_SETTINGS["seed000"],
        "pso": SWARM_SETTINGS["seed001"],
    }
    if generations:
        presets = {k: replace(v, generations=generations) for k, v in presets.items()}
    with_pymoo = importlib.util.find_spec("pymoo") is not None
    figures: dict[str, object] = {}
    ratios: dict[str, float] = {}
    print(f"{'search':<40}{'CPU s':>9}{'best objective rad/s':>24}")
    for kind, settings in presets.items():
        label = f"{kind} {settings.population}x{settings.generations}"
        ours(objective, space, replace(settings, generations=2))  # first-call costs outside the timing
        seconds, best = cpu_s(lambda s=settings: ours(objective, space, s))
        evaluations = settings.population * (settings.generations + 1)
        population = np.random.default_rng(SEED).uniform(
            space.lower, space.upper, (settings.population, space.lower.size)
        )
        eval_s, _ = cpu_s(lambda s=settings, p=population: [objective(p) for _ in range(s.generations + 1)])
        case: dict[str, object] = {
            "population": settings.population,
            "generations": settings.generations,
            "evaluations": evaluations,
            "numpy_cpu_s": seconds,
            "numpy_best_objective": best,
            "objective_alone_cpu_s": eval_s,
        }
        print(f"{'numpy ' + label:<40}{seconds:>9.2f}{best:>24.9f}")
        if with_pymoo:
            pymoo_search(
                objective, space, replace(settings, generations=2)
            )  # its imports, outside the timing
            theirs_s, theirs = cpu_s(lambda s=settings: pymoo_search(objective, space, s))
            case |= {
                "pymoo_cpu_s": theirs_s,
                "pymoo_best_objective": theirs,
                "pymoo_share_not_objective": 1.0 - eval_s / theirs_s,
            }
            ratios[f"{kind}_pymoo_cpu_over_numpy"] = theirs_s / seconds
            print(f"{'pymoo ' + label:<40}{theirs_s:>9.2f}{theirs:>24.9f}")
            print(
                f"  pymoo / numpy CPU: {theirs_s / seconds:.0f}x; the objective alone: {eval_s:.2f} s "
                f"({1 - eval_s / theirs_s:.1%} of pymoo's CPU is its own bookkeeping)"
            )
        figures[kind] = case
    if not with_pymoo:
        print("pymoo is not installed: no baseline (pip install pymoo to measure it)")
    return figures, ratios


def against_output_error(
    run: DecayRun, truth: dict[str, float], generations: int | None
) -> dict[str, object]:
    """The GA's and PSO's fits against output error's, on the seeds' objective and against the truth."""
    ga_settings, pso_settings = GENETIC_SETTINGS["seed000"], SWARM_SETTINGS["seed001"]
    if generations:
        ga_settings = replace(ga_settings, generations=generations)
        pso_settings = replace(pso_settings, generations=generations)
    OutputErrorFit(MODEL).fit(run)  # compile the numba kernels outside the timing
    oe_times = []
    for _ in range(OE_REPEATS):
        seconds, oe = cpu_s(lambda: OutputErrorFit(MODEL).fit(run))
        oe_times.append(seconds)
    fits: dict[str, tuple[float, GeneticSeedFit | SwarmSeedFit | OutputErrorFit]] = {
        "ga": cpu_s(lambda: GeneticSeedFit(MODEL, settings=ga_settings, random_state=SEED).fit(run)),
        "pso": cpu_s(lambda: SwarmSeedFit(MODEL, settings=pso_settings, random_state=SEED).fit(run)),
        "oe": (statistics.median(oe_times), oe),
    }
    amplitude = np.deg2rad(5.0)
    truth_objective = seed_objective(tuple(truth), np.array(list(truth.values())), [run], [0.0])
    truth_beq, truth_t0 = b_eq(truth, amplitude), natural_period(truth)
    print()
    print(f"{'coefficient':<12}" + "".join(f"{k:>11}" for k in truth))
    print(f"{'truth':<12}" + "".join(f"{v:>11.4g}" for v in truth.values()))
    for name, (_, fit) in fits.items():
        print(f"{name:<12}" + "".join(f"{fit.coefficients_[k]:>11.4g}" for k in truth))
    print()
    print(
        f"{'fit':<12}{'CPU s':>9}{'seed obj rad/s':>16}{'vs truth':>10}{'R2 angle':>10}"
        f"{'B_eq(5deg)':>12}{'T0':>9}"
    )
    figures: dict[str, object] = {"truth_seed_objective": truth_objective}
    for name, (seconds, fit) in fits.items():
        objective, r2 = fit.seed_objective_, fit.r2_angle_
        beq = b_eq(fit.coefficients_, amplitude) / truth_beq - 1
        t0 = natural_period(fit.coefficients_) / truth_t0 - 1
        print(
            f"{name:<12}{seconds:>9.3f}{objective:>16.6f}{objective / truth_objective - 1:>+10.3%}{r2:>10.4f}"
            f"{beq:>+12.1%}{t0:>+9.2%}"
        )
        figures[name] = {
            "cpu_s": seconds,
            "seed_objective": objective,
            "r2_angle": r2,
            "b_eq_5deg_rel_error": beq,
            "b1": fit.coefficients_["b1"],
        }
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generations", type=int, help="both presets' generations (default: the papers')")
    generations = parser.parse_args().generations
    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    run = noisy_decay(truth)
    print(f"model {MODEL} on {run.name}: {run.t.size} samples, 5 deg release, noise 1e-3 rad / 0.01 rad/s\n")
    search_figures, ratios = searches(run, generations)
    fit_figures = against_output_error(run, truth, generations)
    write_result(
        "seed_search",
        "the seeds' GA (seed 000 preset) and PSO (seed 001 preset) on one known-truth SWATH decay (15 s, "
        "100 Hz): tankdaq's numpy search against pymoo's on the same objective, box, settings and seed (CPU "
        "s, best objective); the fits against output error (objective, R2, B_eq error)",
        counts={"samples": run.t.size, "oe_repeats": OE_REPEATS, "seed": SEED},
        figures={"search": search_figures, "fits": fit_figures},
        ratios=ratios,
        baseline="pymoo 0.6 GA (SBX, PM) and adaptive PSO, same run (absent where pymoo is not installed)",
        quick=generations is not None,
    )


if __name__ == "__main__":
    main()
