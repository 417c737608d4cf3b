"""Every estimator keeps one contract: settings read back from the constructor, clone, fit leaves the
settings as given, and a result asked for before fit says to call fit."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from tankdaq.acquire.release import ReleaseDetector
from tankdaq.auv.identify import LeastSquaresRegressor, LSSVMRegressor, SeparateIdentifier
from tankdaq.auv.model import simulate_zigzag
from tankdaq.auv.vehicle import load_vehicle
from tankdaq.config.hulls import hull_scenario
from tankdaq.diagnose.synthetic import make_decay_set
from tankdaq.diagnose.workflow import Diagnoser
from tankdaq.errors import InputError, NotFittedError
from tankdaq.ident.base import Estimator
from tankdaq.ident.equation_error import EquationErrorFit
from tankdaq.ident.evolutionary import GeneticSeedFit, GeneticSettings, SwarmSeedFit, SwarmSettings
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.live.identifier import OnlineIdentifier

RUNS = make_decay_set([], seed=21, duration_s=8.0).runs
RNG = np.random.default_rng(0)
X = RNG.normal(size=(200, 3))
Y = X @ np.array([1.0, -2.0, 0.5]) + 0.1 + RNG.normal(0, 0.01, 200)
NPS = load_vehicle("nps_auv2")


def _feed_online(identifier: OnlineIdentifier) -> None:
    run = RUNS[0]
    identifier.update(run.t, run.angle, run.rate)
    identifier.finish()


#: (class, settings unlike the defaults, how to fit it)
CASES: list[tuple[type, dict[str, Any], Callable[[Any], object]]] = [
    (OutputErrorFit, {"terms": "b1,c1", "fit_gain": True, "cov_type": "classic"}, lambda e: e.fit(RUNS)),
    (EquationErrorFit, {"terms": ("b1", "c1"), "window_periods": 0.2}, lambda e: e.fit(RUNS)),
    (
        GeneticSeedFit,
        {
            "terms": "seed001-eq1",
            "settings": GeneticSettings(population=10, generations=3),
            "random_state": 4,
        },
        lambda e: e.fit(RUNS),
    ),
    (
        SwarmSeedFit,
        {"terms": "seed001-eq1", "settings": SwarmSettings(population=10, generations=3), "random_state": 5},
        lambda e: e.fit(RUNS),
    ),
    (OnlineIdentifier, {"terms": "b1,c1", "min_half_cycles": 4, "cov_type": "classic"}, _feed_online),
    (LeastSquaresRegressor, {}, lambda e: e.fit(X, Y)),
    (LSSVMRegressor, {"gammas": [1.0, 100.0], "n_folds": 3}, lambda e: e.fit(X, Y)),
    (
        SeparateIdentifier,
        {"vehicle": NPS, "method": "ols", "window_s": 2.0},
        lambda e: e.fit(simulate_zigzag(NPS, np.radians(15.0), np.radians(10.0), switches=4)),
    ),
    (
        ReleaseDetector,
        {"axis": "roll", "settle_deg": 0.4},
        lambda e: e.fit(hull_scenario(runs=1, seed=3, rate_hz=100).samples()[0]),
    ),
    (Diagnoser, {"baseline": "b1,c1", "max_steps": 0}, lambda e: e.fit(RUNS)),
]
IDS = [cls.__name__ for cls, _, _ in CASES]


@pytest.mark.parametrize(("cls", "settings", "fit"), CASES, ids=IDS)
def test_get_params_reads_the_constructor_and_clone_round_trips(cls, settings, fit) -> None:
    estimator = cls(**settings)
    assert isinstance(estimator, Estimator) or cls is OnlineIdentifier  # fed by update(), not fit()
    params = estimator.get_params()
    assert {k: params[k] for k in settings} == settings
    defaults = cls().get_params() if cls is not SeparateIdentifier else None
    if defaults is not None:
        assert set(defaults) | set(settings) == set(params)  # every setting, given or not
    twin = estimator.clone()
    assert type(twin) is cls and twin is not estimator
    assert twin.get_params() == params
    for name, value in params.items():
        if isinstance(value, list | dict):
            assert getattr(twin, name) is not value, f"{name} is shared between clones"


@pytest.mark.parametrize(("cls", "settings", "fit"), CASES, ids=IDS)
@pytest.mark.slow
def test_fit_leaves_the_settings_as_given(cls, settings, fit) -> None:
    estimator = cls(**settings)
    before = estimator.get_params()
    fit(estimator)
    assert estimator.get_params() == before
    assert estimator.clone().get_params() == before
    if cls is not ReleaseDetector and cls is not OnlineIdentifier:  # those two hold state from the start
        assert estimator.fitted and not estimator.clone().fitted


def test_clone_takes_changes() -> None:
    estimator = OutputErrorFit("b1,c1", cov_type="classic")
    assert estimator.clone(compute_diagnostics=False).get_params() == {
        **estimator.get_params(),
        "compute_diagnostics": False,
    }
    online = OnlineIdentifier("b1,c1", reweight=False)
    assert online.get_params()["reweight"] is False
    assert online.clone().estimator_settings == {"reweight": False}


@pytest.mark.parametrize(
    "call",
    [
        lambda: OutputErrorFit().predict(np.arange(100) / 100.0),
        lambda: OutputErrorFit().coefficients_,
        lambda: EquationErrorFit().offsets_,
        lambda: GeneticSeedFit().coefficients_,
        lambda: LSSVMRegressor().predict(X),
        lambda: LeastSquaresRegressor().predict(X),
        lambda: SeparateIdentifier(NPS).model(),
        lambda: Diagnoser().final_,
    ],
    ids=["oe-predict", "oe", "ee", "ga", "lssvm", "ols", "separate", "diagnoser"],
)
def test_a_result_before_fit_says_to_call_fit(call: Callable[[], object]) -> None:
    with pytest.raises(NotFittedError, match=r"call fit\(\.\.\.\) first"):
        call()


def test_a_missing_attribute_after_fit_is_a_plain_attribute_error() -> None:
    fitted = EquationErrorFit("b1,c1").fit(RUNS)
    with pytest.raises(AttributeError) as raised:
        _ = fitted.gain_
    assert not isinstance(raised.value, NotFittedError)


@pytest.mark.parametrize(("cls", "settings", "fit"), CASES, ids=IDS)
def test_set_params_changes_settings_by_name(cls, settings, fit) -> None:
    estimator = cls(NPS) if cls is SeparateIdentifier else cls()
    assert estimator.set_params(**settings) is estimator
    assert estimator.get_params() == cls(**settings).get_params()
    if cls is not OnlineIdentifier:  # its **settings go on to the estimator it refits, as in its constructor
        with pytest.raises(InputError, match="has no setting 'no_such_setting'"):
            estimator.set_params(no_such_setting=1)


class _Interruptible(OutputErrorFit):
    """An output-error fit that can be interrupted inside its solve, after its runs and terms are known."""

    interrupt = False

    def _solve(self, p0: np.ndarray, free: np.ndarray, tol: float) -> np.ndarray:
        if self.interrupt:
            raise KeyboardInterrupt  # what Ctrl-C does in the middle of a fit
        return super()._solve(p0, free, tol)


def test_a_fit_that_fails_leaves_no_result() -> None:
    estimator = _Interruptible("b1,c1")
    estimator.interrupt = True
    with pytest.raises(KeyboardInterrupt):
        estimator.fit(RUNS)
    assert not estimator.fitted
    with pytest.raises(NotFittedError):
        _ = estimator.terms_


def test_a_refit_that_fails_keeps_the_results_of_the_last_success() -> None:
    estimator = _Interruptible("b1,c1").fit(RUNS)
    before = dict(estimator.coefficients_)
    estimator.interrupt = True
    with pytest.raises(KeyboardInterrupt):
        estimator.fit(RUNS[:1])
    assert estimator.coefficients_ == before
    assert len(estimator.runs_) == len(RUNS)  # not the runs of the fit that failed
