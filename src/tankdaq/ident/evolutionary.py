"""The seeds' own identification: a genetic algorithm (seeds 000-002) and a particle swarm (seed 001).

The papers searched the total inertia I and dimensional coefficients (N, W, x, C1, C2, C3 ...) inside
fixed boxes, minimising the RMS of the one-step-ahead predicted angular velocity (seed 000 eq. 4.5-4.6,
seed 001 eq. 6-7). tankdaq reruns that search (``population_search``: the papers' GA and PSO in numpy)
so the papers' tables can be reproduced and set against output error (docs/seeds.md). Only ratios to I
are identifiable, so results are reported as tankdaq terms (b1..s3) like every other estimator; the
seeds' own variables, I included, stay in ``seed_variables_``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property, partial

import numpy as np

from ..config.validation import equation_model
from ..errors import InputError
from ..physics.models import MODEL_ALIASES
from ..records import DecayRun
from .base import EstimatorMixin
from .compiled import simulate, substeps, term_codes, term_matrix
from .equation_error import check_runs
from .population_search import Objective, Progress, SearchResult, genetic_algorithm, particle_swarm
from .uncertainty import coefficient_warnings

#: Lower bound of the total inertia. The papers write I in [0, 0.1]; 0 itself would divide by zero.
INERTIA_FLOOR = 1e-3


# --------------------------------------------------------------------------------------------------
# The seeds' objective: RMS of the one-step-ahead predicted angular velocity
# --------------------------------------------------------------------------------------------------


def _measured_rate(run: DecayRun) -> np.ndarray:
    """The gyro rate when the run has one, else the angle differentiated (the seeds always had the gyro)."""
    return run.rate if run.rate is not None else np.gradient(run.angle, run.t)


@dataclass(frozen=True)
class OneStepData:
    """Every consecutive sample pair (k, k+1) of a set of runs, arranged for the seeds' predictor.

    The seeds predict the rate at k+1 from the state measured at k with one Euler step,
    ``rate[k] + dt_k * x''(angle[k], rate[k])``, so the residual ``change + design @ theta`` is
    linear in the coefficients. Its mean square is a quadratic form whose sums are taken once over
    the samples; a whole population then costs one small matrix product, whatever the record length.
    """

    terms: tuple[str, ...]
    design: np.ndarray  # (pairs, terms): dt_k * regressor_k
    change: np.ndarray  # (pairs,): rate[k+1] - rate[k]

    @classmethod
    def from_runs(cls, runs: Sequence[DecayRun], terms: Sequence[str]) -> OneStepData:
        codes = term_codes(terms)
        designs, changes = [], []
        for run in runs:
            rate = _measured_rate(run)
            phi = term_matrix(codes, run.angle[:-1], rate[:-1], np.zeros(run.t.size - 1), 1.0)
            designs.append(np.diff(run.t)[:, None] * phi)
            changes.append(np.diff(rate))
        return cls(tuple(terms), np.concatenate(designs), np.concatenate(changes))

    @cached_property
    def _moments(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(D'D, D'change, change'change) / pairs: everything the mean square needs."""
        m = self.change.size
        return (
            self.design.T @ self.design / m,
            self.design.T @ self.change / m,
            float(self.change @ self.change) / m,
        )

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Measured minus predicted rate at every k+1 for one coefficient vector, rad/s."""
        return self.change + self.design @ theta

    def rms(self, theta: np.ndarray) -> np.ndarray:
        """Seed objective F of each row of ``theta`` (individuals x terms), rad/s."""
        gram, cross, total = self._moments
        theta = np.atleast_2d(theta)
        mean_square = total + 2.0 * theta @ cross + np.einsum("ij,jk,ik->i", theta, gram, theta)
        return np.sqrt(np.clip(mean_square, 0.0, None))


# --------------------------------------------------------------------------------------------------
# What the papers searched: their variables, boxes and how each maps onto a tankdaq term
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SeedVariable:
    """One design variable of a paper: tankdaq ``term`` = ``factor`` * value / I, value in [0, high]."""

    symbol: str
    term: str
    high: float
    factor: float = 1.0


def _variables(spec: str) -> dict[str, SeedVariable]:
    """Parse 'term:symbol:high[:factor]' items (every box starts at 0 in the papers)."""
    out = {}
    for item in spec.split():
        term, symbol, high, *factor = item.split(":")
        out[term] = SeedVariable(symbol, term, float(high), float(factor[0]) if factor else 1.0)
    return out


_SWATH_BOXES = "b1:N:1:2 b2:W:1 b3:x:10 c1:C3:10 c2:C2:10 c3:C1:10 s1:C3:10 s2:C2:10 s3:C1:10"

#: Per paper: each term's symbol and box. Seed 001 eq. 2 and seed 002 Table 3 print theirs; seed 000's
#: Table 3 covers eq. 1 only (M, V, gamma, H), so tankdaq reuses H's box for its C1..C3.
PAPER_VARIABLES: dict[str, dict[str, SeedVariable]] = {
    "seed000": _variables(
        "b1:M:0.5:2 b2:V:0.5 b3:gamma:0.2 c1:C3:0.5 c2:C2:0.5 c3:C1:0.5 s1:H:0.5 s2:C2:0.5 s3:C1:0.5"
    ),
    "seed001": _variables(_SWATH_BOXES),
    "seed002": _variables(_SWATH_BOXES),
}

#: The boxes a term list that is not a seed alias gets.
DEFAULT_PAPER = "seed001"


@dataclass(frozen=True)
class SearchSpace:
    """The box a paper searched: total inertia I first, then one variable per term."""

    paper: str
    variables: tuple[SeedVariable, ...]
    inertia_high: float = 0.1

    @classmethod
    def for_model(cls, model: str | Sequence[str], paper: str | None = None) -> SearchSpace:
        """The boxes of ``paper``; by default an alias's own paper's (``seed000-eq1``), else seed 001's."""
        terms = equation_model(model, "the seeds' GA/PSO search", "drop them or use --method oe")
        if paper is None:
            alias = model.strip().lower() if isinstance(model, str) else ""
            paper = (
                alias.split("-")[0] if alias in MODEL_ALIASES and alias.startswith("seed") else DEFAULT_PAPER
            )
        if paper not in PAPER_VARIABLES:
            raise InputError(f"no seed paper {paper!r}; known: {', '.join(PAPER_VARIABLES)}")
        return cls(paper, tuple(PAPER_VARIABLES[paper][term] for term in terms))

    @property
    def terms(self) -> tuple[str, ...]:
        return tuple(v.term for v in self.variables)

    @property
    def symbols(self) -> tuple[str, ...]:
        """The papers' symbols, with the term added where two terms share one (C3 is c1's and s1's)."""
        counts = [v.symbol for v in self.variables].count
        return tuple(v.symbol if counts(v.symbol) == 1 else f"{v.symbol}[{v.term}]" for v in self.variables)

    @property
    def lower(self) -> np.ndarray:
        return np.array([INERTIA_FLOOR] + [0.0] * len(self.variables))

    @property
    def upper(self) -> np.ndarray:
        return np.array([self.inertia_high] + [v.high for v in self.variables])

    def coefficients(self, x: np.ndarray) -> np.ndarray:
        """Design vectors (individuals x [I, vars...]) -> tankdaq coefficients (individuals x terms)."""
        x = np.atleast_2d(x)
        factors = np.array([v.factor for v in self.variables])
        return factors * x[:, 1:] / x[:, :1]


# --------------------------------------------------------------------------------------------------
# Settings as the papers printed them
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GeneticSettings:
    """The papers' GA: population, generations ("optimized algebra"), crossover and mutation probability."""

    population: int = 200
    generations: int = 2000
    crossover: float = 0.8
    mutation: float = 0.15

    def __post_init__(self) -> None:
        _check_settings(self, {"crossover": self.crossover, "mutation": self.mutation})

    def search(
        self,
        objective: Objective,
        lower: np.ndarray,
        upper: np.ndarray,
        rng: np.random.Generator,
        progress: Progress | None = None,
    ) -> SearchResult:
        """The GA with these settings on ``objective`` in the box [``lower``, ``upper``]."""
        return genetic_algorithm(
            objective, lower, upper, population=self.population, generations=self.generations,
            crossover=self.crossover, mutation=self.mutation, rng=rng, progress=progress,
        )  # fmt: skip


@dataclass(frozen=True)
class SwarmSettings:
    """Seed 001's PSO: population, iterations, max particle speed as a fraction of each variable's range.

    The inertia weight moves from 0.9 to 0.4 over the iterations, the paper's "variable weight 0.4-0.9".
    """

    population: int = 200
    generations: int = 1000
    max_velocity: float = 0.15

    def __post_init__(self) -> None:
        _check_settings(self, {"max_velocity": self.max_velocity})

    def search(
        self,
        objective: Objective,
        lower: np.ndarray,
        upper: np.ndarray,
        rng: np.random.Generator,
        progress: Progress | None = None,
    ) -> SearchResult:
        """The PSO with these settings on ``objective`` in the box [``lower``, ``upper``]."""
        return particle_swarm(
            objective, lower, upper, particles=self.population, iterations=self.generations,
            max_velocity=self.max_velocity, rng=rng, progress=progress,
        )  # fmt: skip


def _check_settings(settings: GeneticSettings | SwarmSettings, fractions: dict[str, float]) -> None:
    """A search needs two individuals, one generation, and probabilities and speed limits in [0, 1]."""
    name, size = type(settings).__name__, (settings.population, settings.generations)
    if not all(isinstance(n, int) and not isinstance(n, bool) for n in size) or size[0] < 2 or size[1] < 1:
        raise InputError(
            f"{name} needs whole numbers population >= 2, generations >= 1, not {size[0]!r} and {size[1]!r}"
        )
    for field, value in fractions.items():
        if not isinstance(value, int | float) or isinstance(value, bool) or not 0.0 <= value <= 1.0:
            raise InputError(f"{name}.{field} is a fraction in [0, 1], not {value!r}")


GENETIC_SETTINGS: dict[str, GeneticSettings] = {
    "seed000": GeneticSettings(population=200, generations=2000, crossover=0.8, mutation=0.15),
    # scheme 1 ran 1000 "calculation times" with mutation 0.1; the paper then settled on 0.15
    "seed001": GeneticSettings(population=200, generations=1000, crossover=0.8, mutation=0.15),
    # seed 002 prints no generation count: tankdaq uses seed 000's 2000 (same group, same software)
    "seed002": GeneticSettings(population=400, generations=2000, crossover=0.7, mutation=0.15),
}

SWARM_SETTINGS: dict[str, SwarmSettings] = {
    "seed001": SwarmSettings(population=200, generations=1000, max_velocity=0.15),
}


# --------------------------------------------------------------------------------------------------
# The estimators
# --------------------------------------------------------------------------------------------------


class _SeedSearch(EstimatorMixin):
    """Shared fit of GeneticSeedFit and SwarmSeedFit: the paper's box, a search, results as tankdaq terms.

    Settings: ``terms`` (term list or alias), ``paper`` (whose boxes and preset: ``seed000``,
    ``seed001``, ``seed002``; default the alias's paper, else seed 001), ``settings`` (a preset name
    or a settings object, overriding the paper's preset), ``random_state``, ``progress`` (called
    with (generation, generations) after each generation).
    """

    #: What ``std_`` and ``ci95_`` mean, for reports: the curvature of the seeds' objective.
    cov_type = "one-step least squares"

    _presets: Mapping[str, GeneticSettings | SwarmSettings]
    _settings_type: type

    def __init__(
        self,
        terms: str | Sequence[str] = "seed001-eq1",
        *,
        paper: str | None = None,
        settings: str | GeneticSettings | SwarmSettings | None = None,
        random_state: int = 0,
        progress: Callable[[int, int], None] | None = None,
    ) -> None:
        self.terms = terms
        self.paper = paper
        self.settings = settings
        self.random_state = random_state
        self.progress = progress

    def _resolved_settings(self, paper: str) -> GeneticSettings | SwarmSettings:
        settings = self.settings
        preset = (GeneticSettings, SwarmSettings)
        if isinstance(settings, preset) and isinstance(settings, self._settings_type):
            return settings
        if self.settings is not None and not isinstance(self.settings, str):
            raise InputError(f"{type(self).__name__} takes {self._settings_type.__name__} or a preset name")
        name = self.settings or (paper if paper in self._presets else next(iter(self._presets)))
        if name not in self._presets:
            known = ", ".join(self._presets)
            raise InputError(f"no {type(self).__name__} settings named {name!r}; known: {known}")
        return self._presets[name]

    def fit(self, runs: DecayRun | Sequence[DecayRun]) -> _SeedSearch:
        """Search the paper's box for the smallest seed objective over all runs jointly; returns self."""
        started = time.perf_counter()
        self.runs_ = check_runs(runs)
        self.space_ = SearchSpace.for_model(self.terms, self.paper)
        self.settings_ = self._resolved_settings(self.space_.paper)
        data = OneStepData.from_runs(self.runs_, self.space_.terms)
        space = self.space_
        rng = np.random.default_rng(self.random_state)
        result = self.settings_.search(
            lambda x: data.rms(space.coefficients(x)), space.lower, space.upper, rng, self.progress
        )
        best_x = result.best
        theta = self.space_.coefficients(best_x)[0]
        self.terms_ = self.space_.terms
        self.seed_variables_ = {"I": float(best_x[0])} | dict(
            zip(self.space_.symbols, best_x[1:].tolist(), strict=True)
        )
        self.coefficients_ = dict(zip(self.terms_, theta.tolist(), strict=True))
        self.seed_objective_ = float(data.rms(theta)[0])
        self.history_ = result.history
        self.n_evaluations_ = result.evaluations
        self._set_uncertainty(data, theta)
        self._set_angle_fit(theta)
        self.warnings_ = self._bound_warnings(best_x) + coefficient_warnings(
            self.terms_, theta, np.array(list(self.std_.values())), self.correlation_
        )
        self.elapsed_s_ = time.perf_counter() - started
        return self

    def _bound_warnings(self, best_x: np.ndarray) -> list[str]:
        """Seed variables left on an edge of the paper's box: the box, not the data, decided them."""
        names = ("I", *self.space_.symbols)
        span = self.space_.upper - self.space_.lower
        out = []
        for name, value, low, high, width in zip(
            names, best_x, self.space_.lower, self.space_.upper, span, strict=True
        ):
            edge = (
                "lower" if value - low <= 1e-6 * width else "upper" if high - value <= 1e-6 * width else None
            )
            if edge:
                out.append(f"{name} = {value:.4g} sits on the {edge} bound of the {self.space_.paper} box")
        return out

    def _set_uncertainty(self, data: OneStepData, theta: np.ndarray) -> None:
        """Standard errors from the curvature of the seeds' objective (least squares in theta).

        They measure how flat the objective is around the optimum, which is what lets a GA wander.
        """
        residual = data.residuals(theta)
        sigma2 = float(residual @ residual) / max(1, residual.size - theta.size)
        self.covariance_ = sigma2 * np.linalg.pinv(data.design.T @ data.design)
        std = np.sqrt(np.clip(np.diag(self.covariance_), 0.0, None))
        self.std_ = dict(zip(self.terms_, std.tolist(), strict=True))
        self.ci95_ = {
            k: (v - 1.96 * s, v + 1.96 * s) for (k, v), s in zip(self.coefficients_.items(), std, strict=True)
        }
        scale = np.where(std > 0, std, 1.0)
        self.correlation_ = self.covariance_ / np.outer(scale, scale)

    def _set_angle_fit(self, theta: np.ndarray) -> None:
        """Simulate each run from its measured first state (the seeds fit no initial state or offset).

        R² and NRMSE of the angle are output error's yardsticks, so the two methods compare directly.
        """
        codes = term_codes(self.terms_)
        amplitude = max(float(np.max(np.abs(run.angle))) for run in self.runs_)
        dt_max = max(float(np.max(np.diff(run.t))) for run in self.runs_)
        n_sub = substeps(dt_max, theta, self.terms_, amplitude)
        self.offsets_ = [0.0] * len(self.runs_)
        self.initial_states_ = [(float(run.angle[0]), float(_measured_rate(run)[0])) for run in self.runs_]
        self.fitted_, self.residuals_ = [], []
        for run, (angle0, rate0) in zip(self.runs_, self.initial_states_, strict=True):
            angle, rate = simulate(run.t, angle0, rate0, theta, codes, np.zeros_like(run.t), 1.0, n_sub)
            self.fitted_.append({"angle": angle, "rate": rate})
            self.residuals_.append(
                {"angle": run.angle - angle, "rate": None if run.rate is None else run.rate - rate}
            )
        res = np.concatenate([r["angle"] for r in self.residuals_])
        all_angle = np.concatenate([run.angle for run in self.runs_])
        ss_tot = sum(float(np.sum((run.angle - run.angle.mean()) ** 2)) for run in self.runs_)
        self.r2_angle_ = 1.0 - float(res @ res) / ss_tot
        self.nrmse_ = math.sqrt(float(res @ res) / res.size) / float(np.ptp(all_angle))
        stiffness = self.coefficients_.get("c1", 0.0) + self.coefficients_.get("s1", 0.0)
        self.natural_period_s_ = 2.0 * math.pi / math.sqrt(stiffness) if stiffness > 0 else float("nan")


class GeneticSeedFit(_SeedSearch):
    """The seeds' genetic algorithm (tournament, SBX crossover, polynomial mutation) on their objective.

    ``GeneticSeedFit("seed001-eq1").fit(runs)``; ``settings`` takes a preset name (``seed000``,
    ``seed001``, ``seed002``) or ``GeneticSettings``.
    """

    _presets = GENETIC_SETTINGS
    _settings_type = GeneticSettings


class SwarmSeedFit(_SeedSearch):
    """Seed 001's particle swarm (inertia weight 0.9 to 0.4, speed limit per variable) on their objective."""

    _presets = SWARM_SETTINGS
    _settings_type = SwarmSettings


#: ``--method`` names of the seeds' searches; ``ga-seed000`` etc. pin a paper's boxes and preset, since
#: the CLI hands estimators the model as a term list, not as the alias.
SEED_ESTIMATORS: dict[str, Callable[..., _SeedSearch]] = {
    "ga": GeneticSeedFit,
    "pso": SwarmSeedFit,
    **{f"ga-{paper}": partial(GeneticSeedFit, paper=paper) for paper in GENETIC_SETTINGS},
}
