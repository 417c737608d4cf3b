"""The seeds' GA and PSO: their objective, their boxes, and what they find on known-truth decays."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from tankdaq.config.hulls import load_hull
from tankdaq.errors import BadIdentificationInput, InputError
from tankdaq.ident.derived import damping_ratio
from tankdaq.ident.estimators import make_estimator, reports_progress
from tankdaq.ident.evolutionary import (
    INERTIA_FLOOR,
    GeneticSeedFit,
    GeneticSettings,
    OneStepData,
    SearchSpace,
    SwarmSeedFit,
    SwarmSettings,
)
from tankdaq.ident.one_step import seed_objective
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.physics.decay import acceleration, simulate_decay
from tankdaq.records import DecayRun

SWATH_ROLL_T = load_hull("swath").simulation_model("roll").coefficients(1.0)
QUICK_GA = GeneticSettings(population=200, generations=150)


def swath_decay(angle_deg: float = 5.0, angle_noise: float = 1e-3, rate_noise: float = 0.01, seed: int = 1):
    """15 s of the SWATH roll decay at 100 Hz with white noise on angle (rad) and gyro (rad/s)."""
    t = np.arange(0.0, 15.0, 0.01)
    angle, rate = simulate_decay(SWATH_ROLL_T, t, np.deg2rad(angle_deg))
    rng = np.random.default_rng(seed)
    return DecayRun(
        t, angle + rng.normal(0, angle_noise, t.size), rate + rng.normal(0, rate_noise, t.size), name="swath"
    )


@pytest.fixture(scope="module")
def noisy_run() -> DecayRun:
    return swath_decay()


@pytest.fixture(scope="module")
def ga_fit(noisy_run: DecayRun) -> GeneticSeedFit:
    return GeneticSeedFit("seed001-eq1", settings=QUICK_GA, random_state=3).fit(noisy_run)


def objective_at(coefficients: dict[str, float], run: DecayRun) -> float:
    terms = tuple(coefficients)
    return seed_objective(terms, np.array([coefficients[k] for k in terms]), [run], [0.0])


def box_optimum(run: DecayRun, model: str) -> tuple[float, dict[str, float]]:
    """The smallest seed objective anywhere in the paper's box and where it is (bounded linear LS).

    With I free down to its floor each coefficient can reach factor * high / I_floor, so the box
    in coefficient space is [0, factor * high / I_floor] per term.
    """
    space = SearchSpace.for_model(model)
    data = OneStepData.from_runs([run], space.terms)
    high = np.array([v.factor * v.high for v in space.variables]) / INERTIA_FLOOR
    solution = lsq_linear(data.design, -data.change, bounds=(np.zeros_like(high), high))
    return float(data.rms(solution.x)[0]), dict(zip(space.terms, solution.x, strict=True))


@pytest.mark.slow
def test_population_objective_equals_the_euler_prediction_sample_by_sample(noisy_run: DecayRun) -> None:
    space = SearchSpace.for_model("seed001-eq1")
    data = OneStepData.from_runs([noisy_run], space.terms)
    rng = np.random.default_rng(0)
    population = rng.uniform(space.lower, space.upper, size=(5, space.lower.size))
    fast = data.rms(space.coefficients(population))
    for row, value in zip(population, fast, strict=True):
        coefficients = dict(zip(space.terms, space.coefficients(row)[0], strict=True))
        x, v, t = noisy_run.angle, noisy_run.rate, noisy_run.t
        predicted = v[:-1] + np.diff(t) * acceleration(coefficients, x[:-1], v[:-1])
        assert value == pytest.approx(np.sqrt(np.mean((v[1:] - predicted) ** 2)), rel=1e-9)


def test_seed_tables_map_onto_the_hull_coefficients() -> None:
    """Seed 001 Table 4 (I, N, W, x, C1, C2, C3) divided through by I is the swath roll model at T."""
    space = SearchSpace.for_model("seed001-eq1")
    table4 = np.array([0.09484457, 0.01397576, 0.00125340, 1.14244500, 0.00263590, 6.58768553, 1.34854038])
    # design vector order is I then the terms' variables: b1 N, b2 W, b3 x, c1 C3, c2 C2, c3 C1
    design = table4[[0, 1, 2, 3, 6, 4, 5]]
    coefficients = dict(zip(space.terms, space.coefficients(design)[0], strict=True))
    for term, value in SWATH_ROLL_T.items():
        assert coefficients[term] == pytest.approx(value, rel=2e-3), term
    assert [v.symbol for v in space.variables] == ["N", "W", "x", "C3", "C2", "C1"]


def test_seed000_table3_gives_its_equation_5_1() -> None:
    space = SearchSpace.for_model("seed000-eq1")
    assert space.paper == "seed000" and space.terms == ("b1", "b2", "b3", "s1")
    table3 = np.array([0.090243325, 0.098322896, 0.000479988, 0.001392731, 1.30e-05])
    b1, b2, b3, s1 = space.coefficients(table3)[0]
    assert (b1, b2, b3) == pytest.approx((2.1791, 0.00532, 0.015433), rel=2e-3)
    assert s1 == pytest.approx(0.000145, rel=0.02)
    assert space.upper.tolist() == [0.1, 0.5, 0.5, 0.2, 0.5]


def test_seed000_equation_5_1_does_not_oscillate() -> None:
    """docs/seeds.md: eq. 5.1 is overdamped either way it is read, unlike the paper's own Fig. 3."""
    space = SearchSpace.for_model("seed000-eq1")
    table3 = np.array([0.090243325, 0.098322896, 0.000479988, 0.001392731, 1.30e-05])
    coefficients = dict(zip(space.terms, space.coefficients(table3)[0], strict=True))
    assert damping_ratio(coefficients) > 50
    assert damping_ratio({"b1": coefficients["b1"], "c1": coefficients["s1"] + 0.00532}) > 10
    t = np.linspace(0.0, 60.0, 601)
    angle, _ = simulate_decay(coefficients, t, np.deg2rad(2.0))
    assert np.all(angle > 0) and np.rad2deg(angle[-1]) > 1.99  # never comes back within a minute


def test_a_plain_term_list_gets_seed001_boxes_unless_a_paper_is_named() -> None:
    space = SearchSpace.for_model("b1,b2,c1,c3")
    assert space.paper == "seed001"
    assert space.upper.tolist() == [0.1, 1.0, 1.0, 10.0, 10.0]
    pinned = SearchSpace.for_model(("b1", "b2", "b3", "s1"), paper="seed000")
    assert pinned.upper.tolist() == [0.1, 0.5, 0.5, 0.2, 0.5]
    assert SearchSpace.for_model("b1,c1,s1").symbols == ("N", "C3[c1]", "C3[s1]")
    with pytest.raises(InputError, match="no seed paper 'seed007'"):
        SearchSpace.for_model("b1,c1", paper="seed007")


def test_registry_offers_the_seeds_searches() -> None:
    """``--method ga-seed000`` pins seed 000's boxes although the CLI passes a bare term list."""
    assert isinstance(make_estimator("ga", ("b1", "c1")), GeneticSeedFit)
    assert isinstance(make_estimator("pso", ("b1", "c1")), SwarmSeedFit)
    pinned = make_estimator("ga-seed000", ("b1", "b2", "b3", "s1"))
    assert isinstance(pinned, GeneticSeedFit) and pinned.paper == "seed000"
    assert (
        pinned._resolved_settings(SearchSpace.for_model(pinned.terms, pinned.paper).paper).generations == 2000
    )


@pytest.mark.slow
def test_ga_reaches_the_best_objective_in_the_box(noisy_run: DecayRun, ga_fit: GeneticSeedFit) -> None:
    best, _ = box_optimum(noisy_run, "seed001-eq1")
    assert ga_fit.seed_objective_ <= best * (1 + 1e-4)
    assert ga_fit.seed_objective_ == pytest.approx(objective_at(ga_fit.coefficients_, noisy_run), rel=1e-9)
    # the history is the best of each generation: it never gets worse
    assert np.all(np.diff(ga_fit.history_) <= 1e-15)
    assert ga_fit.history_.size == QUICK_GA.generations


@pytest.mark.slow
def test_ga_matches_the_truth_objective_with_coefficients_far_from_it(
    noisy_run: DecayRun, ga_fit: GeneticSeedFit
) -> None:
    """On a noisy decay the seeds' objective is flat: the truth scores no better than the GA's answer."""
    at_truth = objective_at(SWATH_ROLL_T, noisy_run)
    assert ga_fit.seed_objective_ <= at_truth
    assert at_truth <= ga_fit.seed_objective_ * 1.02
    # ... yet the GA's linear damping is several times the truth (gyro noise biases the one-step fit)
    assert ga_fit.coefficients_["b1"] > 3 * SWATH_ROLL_T["b1"]
    # and the quadratic damping W was pushed against the box's floor, which the fit says
    assert any(w.startswith("W = ") and "lower bound of the seed001 box" in w for w in ga_fit.warnings_)


@pytest.mark.slow
def test_output_error_recovers_the_truth_better_than_the_ga(
    noisy_run: DecayRun, ga_fit: GeneticSeedFit
) -> None:
    oe = OutputErrorFit("seed001-eq1").fit(noisy_run)
    for term in ("b1", "c1", "c3"):
        truth = SWATH_ROLL_T[term]
        assert abs(oe.coefficients_[term] - truth) < abs(ga_fit.coefficients_[term] - truth), term
    assert oe.r2_angle_ > 0.99 > ga_fit.r2_angle_


@pytest.mark.slow
def test_ga_recovers_the_linear_terms_on_a_clean_gyro() -> None:
    """With little gyro noise the seeds' method works: damping and stiffness come back near the truth."""
    run = swath_decay(angle_noise=1e-4, rate_noise=1e-4)
    fit = GeneticSeedFit("seed001-eq1", settings=QUICK_GA).fit(run)
    assert fit.coefficients_["c1"] == pytest.approx(SWATH_ROLL_T["c1"], rel=0.02)
    assert fit.coefficients_["b1"] == pytest.approx(SWATH_ROLL_T["b1"], abs=0.1)
    assert fit.r2_angle_ > 0.95


@pytest.mark.slow
def test_swarm_reaches_the_best_objective_in_the_box(noisy_run: DecayRun) -> None:
    fit = SwarmSeedFit("seed001-eq1", settings=SwarmSettings(population=200, generations=60)).fit(noisy_run)
    assert fit.seed_objective_ <= box_optimum(noisy_run, "seed001-eq1")[0] * (1 + 1e-3)
    assert set(fit.seed_variables_) == {"I", "N", "W", "x", "C1", "C2", "C3"}


@pytest.mark.slow
def test_fit_is_reproducible_and_reports_progress(noisy_run: DecayRun) -> None:
    calls: list[tuple[int, int]] = []
    settings = GeneticSettings(population=40, generations=12)
    first = GeneticSeedFit(
        "b1,c1", settings=settings, random_state=7, progress=lambda d, n: calls.append((d, n))
    )
    second = GeneticSeedFit("b1,c1", settings=settings, random_state=7)
    assert first.fit(noisy_run).coefficients_ == second.fit(noisy_run).coefficients_
    assert calls[-1] == (12, 12) and len(calls) == 12


@pytest.mark.parametrize("method", ["ga", "pso", "ga-seed000"])
@pytest.mark.slow
def test_the_searches_by_method_name_take_their_progress_in_the_constructor(
    method: str, noisy_run: DecayRun
) -> None:
    """What ``identify --method ga`` shows its generations through: a setting, kept by ``clone``."""
    assert reports_progress(method) and not reports_progress("oe") and not reports_progress("ee")
    calls: list[tuple[int, int]] = []
    small = GeneticSettings(40, 5) if method.startswith("ga") else SwarmSettings(40, 5, 0.15)
    estimator = make_estimator(method, "b1,c1", settings=small, progress=lambda d, n: calls.append((d, n)))
    assert estimator.clone().get_params()["progress"] is estimator.progress
    estimator.fit(noisy_run)
    assert calls == [(generation, 5) for generation in range(1, 6)]


def test_each_alias_defaults_to_its_papers_settings() -> None:
    """Seed 002 ran a population of 400 with crossover 0.7; seed 000 has no PSO, so seed 001's is used."""
    assert GeneticSeedFit("seed002-eq1")._resolved_settings("seed002") == GeneticSettings(
        400, 2000, 0.7, 0.15
    )
    assert GeneticSeedFit("seed000-eq1")._resolved_settings("seed000") == GeneticSettings(
        200, 2000, 0.8, 0.15
    )
    assert SwarmSeedFit("seed000-eq1")._resolved_settings("seed000") == SwarmSettings(200, 1000, 0.15)


@pytest.mark.parametrize(
    ("estimator", "message"),
    [
        (GeneticSeedFit("b1,c1,fc", settings=QUICK_GA), "search only"),
        (GeneticSeedFit("b1,c1", settings="seed009"), "no GeneticSeedFit settings"),
        (SwarmSeedFit("b1,c1", settings=QUICK_GA), "takes SwarmSettings"),
        (GeneticSeedFit("b1,zz", settings=QUICK_GA), "unknown model term"),
    ],
)
@pytest.mark.slow
def test_bad_settings_are_input_errors(noisy_run: DecayRun, estimator: GeneticSeedFit, message: str) -> None:
    with pytest.raises(InputError, match=message):
        estimator.fit(noisy_run)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: GeneticSettings(population=1), "population >= 2, generations >= 1, not 1 and 2000"),
        (lambda: SwarmSettings(generations=0), "population >= 2, generations >= 1, not 200 and 0"),
        (lambda: GeneticSettings(mutation=1.5), r"GeneticSettings.mutation is a fraction in \[0, 1\]"),
        (lambda: SwarmSettings(max_velocity=float("nan")), "SwarmSettings.max_velocity is a fraction"),
        (lambda: GeneticSettings(generations=1e400), "generations >= 1, not 200 and inf"),
        (lambda: SwarmSettings(population=True), "whole numbers population >= 2"),
        (lambda: GeneticSettings(crossover="0.8"), r"crossover is a fraction in \[0, 1\], not '0.8'"),
    ],
)
def test_settings_no_search_can_run_are_input_errors(make, message: str) -> None:
    with pytest.raises(InputError, match=message):
        make()


def test_no_runs_is_an_input_error() -> None:
    with pytest.raises(BadIdentificationInput):
        GeneticSeedFit("b1,c1", settings=QUICK_GA).fit([])


@pytest.mark.slow
def test_identify_cli_runs_the_ga(tmp_path: Path, noisy_run: DecayRun) -> None:
    """``tankdaq identify --method ga`` reaches the GA via the estimator registry; it finds the optimum."""
    import json

    from typer.testing import CliRunner

    from tankdaq.cli import app
    from tankdaq.ident.inputs import read_decays

    path = tmp_path / "swath_T_roll_5deg.csv"
    run = noisy_run.window(0, 800)  # 8 s: the report's amplitude grid stays above the noise
    table = np.column_stack([run.t, np.rad2deg(run.angle), np.rad2deg(run.rate)])
    np.savetxt(path, table, delimiter=",", header="time_s,angle_deg,rate_deg_s", comments="")
    result = CliRunner().invoke(app, ["identify", str(path), "--method", "ga", "--model", "b1,c1", "--json"])
    assert result.exit_code == 0, result.output
    printed = json.loads(result.stdout)
    assert printed["method"] == "ga"
    best, where = box_optimum(read_decays(path)[0], "b1,c1")
    assert printed["seed_objective"] <= best * (1 + 1e-4)
    assert printed["coefficients"]["c1"]["value"] == pytest.approx(where["c1"], rel=1e-3)
