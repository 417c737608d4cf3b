"""The seeds' GA (and PSO) against output error on one known-truth decay.

Truth: the SWATH roll model at design draft (seed 001 eq. 8, configs/hulls/swath.toml), released from
5 deg, 15 s at 100 Hz (seed 001 kept the first 15 s), white noise 1e-3 rad on the angle and 0.01 rad/s
on the gyro -- the gyro level that makes the truth's seed objective match the seeds' printed values
(0.0128 rad/s at T, 5 deg). Prints wall time, both objectives and the coefficient errors of each method,
and the objective at the truth.

    .venv/bin/python bench/bench_seed_ga.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from benchjson import write_result
from tankdaq.config.hulls import load_hull
from tankdaq.ident.derived import b_eq, natural_period
from tankdaq.ident.evolutionary import (
    GENETIC_SETTINGS,
    SWARM_SETTINGS,
    GeneticSeedFit,
    OneStepData,
    SearchSpace,
    SwarmSeedFit,
)
from tankdaq.ident.one_step import seed_objective
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.decay import simulate_decay
from tankdaq.records import DecayRun

MODEL = "seed001-eq1"
OE_REPEATS = 20


def noisy_decay(truth: dict[str, float]) -> DecayRun:
    t = np.arange(0.0, 15.0, 0.01)
    angle, rate = simulate_decay(truth, t, np.deg2rad(5.0))
    rng = np.random.default_rng(2026)
    return DecayRun(
        t, angle + rng.normal(0, 1e-3, t.size), rate + rng.normal(0, 0.01, t.size), name="swath-T-5deg"
    )


def angle_rms(fit: OutputErrorFit | GeneticSeedFit) -> float:
    return float(np.sqrt(np.mean(np.concatenate([r["angle"] for r in fit.residuals_]) ** 2)))


def evaluation_only_s(run: DecayRun, population: int, generations: int) -> float:
    """Wall time of the GA's objective evaluations alone (random individuals): what pymoo adds is the rest."""
    space = SearchSpace.for_model(MODEL)
    data = OneStepData.from_runs([run], space.terms)
    rng = np.random.default_rng(0)
    individuals = rng.uniform(space.lower, space.upper, size=(population, space.lower.size))
    started = time.perf_counter()
    for _ in range(generations):
        data.rms(space.coefficients(individuals))
    return time.perf_counter() - started


def main() -> None:
    truth = load_hull("swath").simulation_model("roll").coefficients(1.0)
    run = noisy_decay(truth)
    OutputErrorFit(MODEL).fit(run)  # compile the numba kernels outside the timing
    oe_times = []
    for _ in range(OE_REPEATS):
        started = time.perf_counter()
        oe = OutputErrorFit(MODEL).fit(run)
        oe_times.append(time.perf_counter() - started)
    oe_s = statistics.median(oe_times)
    ga_settings, pso_settings = GENETIC_SETTINGS["seed000"], SWARM_SETTINGS["seed001"]
    ga = GeneticSeedFit(MODEL, settings=ga_settings, random_state=0).fit(run)
    pso = SwarmSeedFit(MODEL, settings=pso_settings, random_state=0).fit(run)
    eval_s = evaluation_only_s(run, ga_settings.population, ga_settings.generations)

    amplitude = np.deg2rad(5.0)
    truth_objective = seed_objective(tuple(truth), np.array(list(truth.values())), [run], [0.0])
    print(f"model {MODEL} on {run.name}: {run.t.size} samples, 5 deg release, noise 1e-3 rad / 0.01 rad/s")
    print()
    print(f"{'coefficient':<34}" + "".join(f"{k:>11}" for k in truth))
    print(f"{'truth':<34}" + "".join(f"{v:>11.4g}" for v in truth.values()))
    rows = [
        (f"GA {ga_settings.population}x{ga_settings.generations} (seed 000 settings)", ga.elapsed_s_, ga),
        (
            f"PSO {pso_settings.population}x{pso_settings.generations} (seed 001 settings)",
            pso.elapsed_s_,
            pso,
        ),
        (f"output error (median of {OE_REPEATS})", oe_s, oe),
    ]
    for label, _, fit in rows:
        print(f"{label:<34}" + "".join(f"{fit.coefficients_[k]:>11.4g}" for k in truth))
    print()
    print(
        f"{'method':<34}{'wall s':>9}{'seed obj rad/s':>16}{'angle RMS rad':>15}{'R2 angle':>10}"
        f"{'B_eq(5deg) err':>16}{'T0 err':>9}"
    )
    truth_beq, truth_t0 = b_eq(truth, amplitude), natural_period(truth)
    print(f"{'truth':<34}{'':>9}{truth_objective:>16.6f}{'':>15}{'':>10}{truth_beq:>16.4f}{truth_t0:>9.4f}")
    for label, seconds, fit in rows:
        print(
            f"{label:<34}{seconds:>9.3f}{fit.seed_objective_:>16.6f}{angle_rms(fit):>15.5f}{fit.r2_angle_:>10.4f}"
            f"{b_eq(fit.coefficients_, amplitude) / truth_beq - 1:>+16.1%}"
            f"{natural_period(fit.coefficients_) / truth_t0 - 1:>+9.2%}"
        )
    print()
    print(f"GA / OE wall time: {ga.elapsed_s_ / oe_s:.0f}x;  PSO / OE: {pso.elapsed_s_ / oe_s:.0f}x")
    print(
        f"GA's {ga_settings.population * ga_settings.generations} evaluations alone: {eval_s:.3f} s "
        f"({eval_s / ga.elapsed_s_:.1%} of its wall time; the rest is pymoo's population bookkeeping)"
    )
    print(
        f"seed objective vs the truth's: GA {ga.seed_objective_ / truth_objective - 1:+.3%}, "
        f"PSO {pso.seed_objective_ / truth_objective - 1:+.3%}, "
        f"OE {oe.seed_objective_ / truth_objective - 1:+.3%}"
    )
    print(f"GA seed variables: {', '.join(f'{k}={v:.5g}' for k, v in ga.seed_variables_.items())}")
    figures = {
        name: {
            "wall_s": seconds,
            "seed_objective": fit.seed_objective_,
            "r2_angle": fit.r2_angle_,
            "b_eq_5deg_rel_error": b_eq(fit.coefficients_, amplitude) / truth_beq - 1,
        }
        for name, (_, seconds, fit) in zip(("ga", "pso", "oe"), rows, strict=True)
    }
    write_result(
        "seed_ga",
        "the seeds' GA and PSO against output error on one known-truth SWATH decay (15 s, 100 Hz): wall "
        "time, "
        "objectives, errors against the truth",
        counts={
            "samples": run.t.size,
            "oe_repeats": OE_REPEATS,
            "ga_population": ga_settings.population,
            "ga_generations": ga_settings.generations,
        },
        figures=figures,
        ratios={"ga_wall_over_oe": ga.elapsed_s_ / oe_s, "pso_wall_over_oe": pso.elapsed_s_ / oe_s},
        baseline="output error, same run",
    )


if __name__ == "__main__":
    main()
