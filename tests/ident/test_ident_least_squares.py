"""The fit's own Levenberg-Marquardt against scipy's MINPACK one, and the fit path without scipy.optimize."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable

import numpy as np
import pytest
from scipy.optimize import least_squares

from tankdaq.ident.least_squares import levenberg_marquardt

Problem = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
T = np.linspace(0.0, 10.0, 201)
RNG = np.random.default_rng(7)
NOISE = RNG.normal(0.0, 0.02, T.size)


def rosenbrock(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rosenbrock's banana as two residuals: the curved valley LM has to follow."""
    return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]]), np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])


def exponential_decay(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a exp(-b t) + c against noisy data: a nonzero minimum."""
    a, b, c = x
    data = 2.0 * np.exp(-0.7 * T) + 0.3 + NOISE
    e = np.exp(-b * T)
    return a * e + c - data, np.column_stack([e, -a * T * e, np.ones_like(T)])


def damped_oscillation(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A exp(-l t) cos(w t + phi), the shape of a roll decay, against noisy data."""
    amp, decay, omega, phase = x
    data = 0.3 * np.exp(-0.15 * T) * np.cos(2.1 * T + 0.4) + NOISE
    e, arg = np.exp(-decay * T), omega * T + phase
    model = amp * e * np.cos(arg)
    jac = np.column_stack([e * np.cos(arg), -T * model, -amp * e * T * np.sin(arg), -amp * e * np.sin(arg)])
    return model - data, jac


def badly_scaled(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A rate of 1e-4 /s and an amplitude of 1e4 fitted together (five decades apart)."""
    t = np.linspace(0.0, 2e4, 101)
    amp, rate = x
    data = 1e4 * np.exp(-1e-4 * t) + 30.0 * np.cos(t / 2e3)
    e = np.exp(-rate * t)
    return amp * e - data, np.column_stack([e, -amp * t * e])


CASES = {
    "rosenbrock": (rosenbrock, [-1.2, 1.0]),
    "exponential decay": (exponential_decay, [1.0, 0.2, 0.0]),
    "damped oscillation": (damped_oscillation, [0.25, 0.1, 2.0, 0.2]),
    "badly scaled": (badly_scaled, [3e3, 3e-4]),
}


@pytest.mark.parametrize("tol", [1e-6, 1e-10])
@pytest.mark.parametrize("name", CASES)
def test_same_minimum_as_minpack(name: str, tol: float) -> None:
    problem, x0 = CASES[name]
    mine = levenberg_marquardt(problem, np.array(x0), xtol=tol, ftol=tol, max_nfev=200)
    scipy = least_squares(
        lambda x: problem(x)[0],
        x0,
        jac=lambda x: problem(x)[1],
        method="lm",
        x_scale="jac",
        xtol=tol,
        ftol=tol,
        max_nfev=200,
    )
    assert mine.status == scipy.status > 0, mine.message
    np.testing.assert_allclose(mine.x, scipy.x, rtol=1e-4 if tol == 1e-6 else 1e-7, atol=1e-12)
    assert mine.cost == pytest.approx(scipy.cost, rel=1e-8, abs=1e-20)
    assert abs(mine.nfev - scipy.nfev) <= 1  # the same algorithm: the same path (here: equal counts)


def test_max_nfev_is_honoured() -> None:
    calls = []

    def counted(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        calls.append(x)
        return rosenbrock(x)

    result = levenberg_marquardt(counted, np.array([-1.2, 1.0]), xtol=1e-12, ftol=1e-12, max_nfev=5)
    assert result.nfev == len(calls) == 5
    assert result.status == 0
    assert result.cost < 0.5 * np.sum(rosenbrock(np.array([-1.2, 1.0]))[0] ** 2)


@pytest.mark.parametrize("outside", ["nan", "penalty"])
def test_step_into_a_non_finite_region_is_backed_off(outside: str) -> None:
    """log(x) = log(0.01) from x = 10: the first Gauss-Newton step lands at x < 0, where the
    residual is undefined (or, like the output-error fit's diverged simulation, a 1e6 penalty)."""
    tried = []

    def log_residual(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tried.append(float(x[0]))
        if x[0] <= 0.0:
            bad = np.nan if outside == "nan" else 1e6
            return np.array([bad]), np.array([[bad if outside == "nan" else 0.0]])
        return np.log(x) - np.log(0.01), np.array([[1.0 / x[0]]])

    result = levenberg_marquardt(log_residual, np.array([10.0]), xtol=1e-10, ftol=1e-10, max_nfev=100)
    assert min(tried) <= 0.0  # it did step outside
    assert result.status > 0, result.message
    assert result.x[0] == pytest.approx(0.01, rel=1e-8)


def test_zero_residual_problem_stops() -> None:
    """A problem met exactly: the Gauss-Newton step hits it and the next iteration stops on gtol."""
    target = np.array([1.0, 2.0, -3.0])

    def shifted(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x - target, np.eye(3)

    result = levenberg_marquardt(shifted, np.zeros(3), xtol=1e-10, ftol=1e-10, max_nfev=100)
    assert result.status == 1, result.message
    assert result.cost == 0.0
    np.testing.assert_array_equal(result.x, target)
    assert result.nfev == 2


def test_zero_residual_nonlinear_problem_stops_at_the_root() -> None:
    """Rosenbrock's minimum is a zero residual: the relative reductions stay large, xtol or gtol stop it."""
    result = levenberg_marquardt(rosenbrock, np.array([-1.2, 1.0]), xtol=1e-10, ftol=1e-10, max_nfev=200)
    assert result.status > 0, result.message
    np.testing.assert_allclose(result.x, [1.0, 1.0], rtol=1e-10)
    assert result.cost < 1e-25


@pytest.mark.slow
def test_fit_path_does_not_import_scipy_optimize() -> None:
    """scipy.optimize costs ~0.4 s to import: the output-error fit (and replay's path) must not pull it."""
    probe = (
        "import json, sys\n"
        "import tankdaq.ident.output_error, tankdaq.live.identifier, tankdaq.acquire.replay\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('scipy.optimize'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == []
