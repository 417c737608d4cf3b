"""The seeds' PSO and GA as numpy population searches, on a toy objective whose box optimum is known."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from tankdaq.ident.population_search import SearchResult, genetic_algorithm, particle_swarm

LOWER = np.array([0.0, -1.0, 1e-3])
UPPER = np.array([1.0, 1.0, 0.1])
#: The free minimum lies outside the box in its second variable: the box optimum is on that wall.
TARGET = np.array([0.3, 1.5, 0.05])
WEIGHTS = np.array([1.0, 4.0, 100.0])
BOX_OPTIMUM = np.array([0.3, 1.0, 0.05])
BEST = 1.0 + 4.0 * 0.5**2

SEARCHES = {
    "pso": partial(particle_swarm, particles=40, iterations=60, max_velocity=0.15),
    "ga": partial(genetic_algorithm, population=40, generations=60, crossover=0.8, mutation=0.15),
}
#: Relative distance to the box optimum each must reach: tests/ident/test_evolutionary.py's tolerances.
TOLERANCE = {"pso": 1e-3, "ga": 1e-4}


def toy(x: np.ndarray) -> np.ndarray:
    """A weighted quadratic bowl, one value per row."""
    return 1.0 + ((x - TARGET) ** 2 * WEIGHTS).sum(axis=1)


def search(method: str, seed: int, objective=toy, progress=None) -> SearchResult:
    return SEARCHES[method](objective, LOWER, UPPER, rng=np.random.default_rng(seed), progress=progress)


@pytest.mark.parametrize("method", SEARCHES)
def test_each_search_reaches_the_box_optimum_of_a_quadratic(method: str) -> None:
    result = search(method, seed=5)
    assert result.objective <= BEST * (1 + TOLERANCE[method])
    assert result.objective == toy(result.best[None, :])[0]
    assert result.best == pytest.approx(BOX_OPTIMUM, abs=0.02)
    assert result.history[-1] == result.objective and np.all(np.diff(result.history) <= 0)


@pytest.mark.parametrize("method", SEARCHES)
def test_every_individual_of_every_generation_stays_in_the_box(method: str) -> None:
    """The objective sees every individual the search makes: the first population, then each generation's."""
    seen: list[np.ndarray] = []

    def watched(x: np.ndarray) -> np.ndarray:
        seen.append(x.copy())
        return toy(x)

    result = search(method, seed=2, objective=watched)
    assert len(seen) == result.history.size + 1
    everyone = np.concatenate(seen)
    assert everyone.shape == (result.evaluations, LOWER.size)
    assert np.all(everyone >= LOWER) and np.all(everyone <= UPPER)
    if method == "pso":  # a particle flying out stops on the wall (the optimum is on one)
        assert np.any(everyone[:, 1] == UPPER[1])


@pytest.mark.parametrize("method", SEARCHES)
def test_the_same_seed_gives_the_same_path_bit_for_bit_and_another_seed_another(method: str) -> None:
    first, again, other = search(method, seed=11), search(method, seed=11), search(method, seed=12)
    assert np.array_equal(first.history, again.history) and np.array_equal(first.best, again.best)
    assert not np.array_equal(first.history, other.history)


@pytest.mark.parametrize("method", SEARCHES)
def test_progress_is_told_once_per_generation(method: str) -> None:
    calls: list[tuple[int, int]] = []
    result = search(method, seed=0, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(generation, 60) for generation in range(1, 61)]
    assert result.history.size == 60
