"""Population searches on a box: the seeds' particle swarm and genetic algorithm, a whole population at once.

Both minimise an objective ``f(X: (n, d)) -> (n,)`` that scores every individual of a generation in one
call (the seeds' objective is one small matrix product per generation, ``evolutionary.OneStepData``), so
a generation costs a handful of array operations. Every individual stays inside the box
``[lower, upper]``. The same ``rng`` state gives the same path, bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: Scores a population: rows are individuals, the result one objective per row (smaller is better).
Objective = Callable[[np.ndarray], np.ndarray]
#: Told (generation, generations) after each generation, 1-based.
Progress = Callable[[int, int], None]

#: Distribution indices of SBX and of polynomial mutation: pymoo's defaults, as docs/seeds.md says.
SBX_ETA = 15.0
MUTATION_ETA = 20.0
#: Shi & Eberhart's acceleration coefficients and inertia weight range (seed 001 prints the range only).
SWARM_C1 = 2.0
SWARM_C2 = 2.0
INERTIA_START = 0.9
INERTIA_END = 0.4


@dataclass(frozen=True)
class SearchResult:
    """Where a search ended: the best point, its objective, the best objective after each generation."""

    best: np.ndarray  # (d,)
    objective: float
    history: np.ndarray  # (generations,), never increasing
    evaluations: int


def particle_swarm(
    objective: Objective,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    particles: int,
    iterations: int,
    max_velocity: float,
    rng: np.random.Generator,
    progress: Progress | None = None,
) -> SearchResult:
    """Global-best particle swarm (Kennedy & Eberhart 1995) with an inertia weight (Shi & Eberhart 1998).

    ``v = w v + c1 r1 (pbest - x) + c2 r2 (gbest - x)``, ``x = x + v``, as seed 001's scheme 2: the
    inertia weight moves linearly from 0.9 to 0.4 over the iterations (Shi & Eberhart 1999, the paper's
    "variable weight 0.4-0.9"), each velocity component is limited to ``max_velocity`` times its
    variable's range (the paper's "maximum speed limit"), c1 = c2 = 2 (the paper prints none). A particle
    that would leave the box stops on its wall: the position is clipped and that velocity component zeroed.
    """
    span = upper - lower
    v_max = max_velocity * span
    x = rng.uniform(lower, upper, size=(particles, lower.size))
    v = rng.uniform(-v_max, v_max, size=x.shape)
    f = objective(x)
    own_x, own_f = x.copy(), f.copy()
    best = int(np.argmin(own_f))
    history = np.empty(iterations)
    for step, w in enumerate(np.linspace(INERTIA_START, INERTIA_END, iterations)):
        r1, r2 = rng.random((2, *x.shape))
        v = w * v + SWARM_C1 * r1 * (own_x - x) + SWARM_C2 * r2 * (own_x[best] - x)
        np.clip(v, -v_max, v_max, out=v)
        x = x + v
        outside = (x < lower) | (x > upper)
        np.clip(x, lower, upper, out=x)
        v[outside] = 0.0
        f = objective(x)
        improved = f < own_f
        own_x[improved], own_f[improved] = x[improved], f[improved]
        best = int(np.argmin(own_f))
        history[step] = own_f[best]
        if progress is not None:
            progress(step + 1, iterations)
    return SearchResult(own_x[best].copy(), float(own_f[best]), history, particles * (iterations + 1))


def genetic_algorithm(
    objective: Objective,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    population: int,
    generations: int,
    crossover: float,
    mutation: float,
    rng: np.random.Generator,
    progress: Progress | None = None,
) -> SearchResult:
    """Real-coded elitist GA, as the seeds' papers set it (population, generations, both probabilities).

    Each generation: ``population`` offspring from parents chosen by binary tournament (Goldberg & Deb
    1991); a pair crosses with probability ``crossover`` by simulated binary crossover (Deb & Agrawal
    1995); each variable of each offspring mutates with probability ``mutation`` by polynomial mutation
    (Deb & Goyal 1996); the best ``population`` of parents and offspring survive (Deb 2001's (mu +
    lambda) survival, pymoo's GA).
    """
    x = rng.uniform(lower, upper, size=(population, lower.size))
    f = objective(x)
    history = np.empty(generations)
    pairs = (population + 1) // 2
    for generation in range(generations):
        parents = _tournament(f, 2 * pairs, rng)
        children = _sbx(x[parents[:pairs]], x[parents[pairs:]], lower, upper, crossover, rng)
        children = _polynomial_mutation(children[:population], lower, upper, mutation, rng)
        x = np.concatenate([x, children])
        f = np.concatenate([f, objective(children)])
        keep = np.argsort(f, kind="stable")[:population]
        x, f = x[keep], f[keep]
        history[generation] = f[0]
        if progress is not None:
            progress(generation + 1, generations)
    return SearchResult(x[0].copy(), float(f[0]), history, population * (generations + 1))


def _tournament(f: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``count`` parents, each the better of two individuals drawn at random (a tie: the first)."""
    a, b = rng.integers(0, f.size, size=(2, count))
    return np.where(f[b] < f[a], b, a)


def _sbx(
    p1: np.ndarray,
    p2: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    rate: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Two children per pair by bounded simulated binary crossover (Deb & Agrawal 1995; Deb's NSGA-II code).

    A pair crosses with probability ``rate``, and then each variable with probability 1/2 (as Deb's code
    and pymoo); a variable's two children are swapped with probability 1/2; the parents are copied otherwise.
    """
    y1, y2 = np.minimum(p1, p2), np.maximum(p1, p2)
    delta = y2 - y1
    cross = (rng.random((p1.shape[0], 1)) < rate) & (rng.random(p1.shape) < 0.5) & (delta > 1e-14)
    u = rng.random(p1.shape)
    safe = np.where(cross, delta, 1.0)
    low = 0.5 * (y1 + y2 - _spread(1.0 + 2.0 * (y1 - lower) / safe, u) * delta)
    high = 0.5 * (y1 + y2 + _spread(1.0 + 2.0 * (upper - y2) / safe, u) * delta)
    swap = rng.random(p1.shape) < 0.5
    c1 = np.where(cross, np.where(swap, high, low), p1)
    c2 = np.where(cross, np.where(swap, low, high), p2)
    return np.clip(np.concatenate([c1, c2]), lower, upper)


def _spread(beta: np.ndarray, u: np.ndarray) -> np.ndarray:
    """SBX's spread factor for a child limited by a bound at ``beta`` (Deb's bounded form)."""
    alpha = 2.0 - beta ** -(SBX_ETA + 1.0)
    base = np.where(u <= 1.0 / alpha, u * alpha, 1.0 / (2.0 - u * alpha))  # beta >= 1: 1 <= alpha < 2
    return base ** (1.0 / (SBX_ETA + 1.0))


def _polynomial_mutation(
    x: np.ndarray, lower: np.ndarray, upper: np.ndarray, rate: float, rng: np.random.Generator
) -> np.ndarray:
    """Each variable moved with probability ``rate`` by bounded polynomial mutation (Deb & Goyal 1996)."""
    span = upper - lower
    mutate = rng.random(x.shape) < rate
    u = rng.random(x.shape)
    power = MUTATION_ETA + 1.0
    below = 1.0 - (x - lower) / span
    above = 1.0 - (upper - x) / span
    down = (2.0 * u + (1.0 - 2.0 * u) * below**power) ** (1.0 / power) - 1.0
    up = 1.0 - (2.0 * (1.0 - u) + 2.0 * (u - 0.5) * above**power) ** (1.0 / power)
    step = np.where(u <= 0.5, down, up)
    return np.clip(np.where(mutate, x + step * span, x), lower, upper)
