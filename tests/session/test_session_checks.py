"""The guided session's pure parts: each acceptance check alone, the scripted faults, the shipped plans."""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Any

import numpy as np
import pytest

from support.measured_decay import measured_decay
from tankdaq.config.hulls import hull_scenario
from tankdaq.errors import InputError
from tankdaq.ident.free_decay import find_free_end
from tankdaq.physics.scenario import parse_fault_script, scripted_run
from tankdaq.records import DecayEnd, DecayRun
from tankdaq.session.checks import Measured, check_decay, usable_measured
from tankdaq.session.plan import Acceptance, PlannedCondition


@pytest.mark.parametrize(
    ("changes", "phrase"),
    [
        ({"angle_deg": 12.0}, "from the nominal 10"),
        ({"still_water_deg": -1.4}, "not level"),
        ({"free_end": "excitation", "free_end_reason": "a second excitation"}, "release not clean"),
        ({"max_rate_deg_s": 299.0}, "rate saturated"),
        ({"half_cycles": 3}, "too short"),
        ({"r2_angle": 0.9}, "poor fit"),
        ({"ended": DecayEnd.DEVICE_LOST}, "cut short (the device went away)"),
        ({"b_eq_per_s": 3.4}, "not a repeat: B_eq"),
        ({"natural_period_s": 1.75}, "not a repeat: period"),
        ({"fit_warnings": ["implausible damping: B_eq -0.05 1/s at 0.0 deg"]}, "fit: implausible damping"),
    ],
)
def test_each_check_flags_its_fault_alone(changes: dict[str, Any], phrase: str) -> None:
    condition, acceptance, earlier = PlannedCondition("T", 10.0), Acceptance(), [measured_decay()]
    assert check_decay(measured_decay(), condition, acceptance, earlier) == []
    reasons = check_decay(measured_decay(**changes), condition, acceptance, earlier)
    assert len(reasons) == 1 and phrase in reasons[0]


def test_a_logged_decay_reads_back_with_how_it_ended_also_from_a_log_before_ended() -> None:
    """The session log keeps each decay's measurements; a log written before ``ended`` says ``settle_reason``
    (``note`` was a stop: never taken for a whole decay on resume)."""
    logged = json.loads(json.dumps(dataclasses.asdict(measured_decay(ended=DecayEnd.TIMEOUT))))
    assert logged["ended"] == "timeout" and Measured.from_log(logged) == measured_decay(
        ended=DecayEnd.TIMEOUT
    )
    del logged["ended"]
    assert usable_measured({**logged, "settle_reason": "amplitude"})
    assert Measured.from_log({**logged, "settle_reason": "amplitude"}).ended is DecayEnd.SETTLED
    stopped = Measured.from_log({**logged, "settle_reason": "note"})
    assert stopped.ended is DecayEnd.STOPPED
    assert not usable_measured({**logged, "ended": "gone fishing"}) and not usable_measured(logged)
    condition, acceptance = PlannedCondition("T", 10.0), Acceptance()
    assert check_decay(stopped, condition, acceptance, []) == ["cut short (stopped by the operator)"]


def test_the_scripted_double_push_is_a_second_excitation() -> None:
    scenario = hull_scenario(hull="swath", runs=1, seed=3, **scripted_run("double-push", 12.0))
    samples, trace = scenario.samples()
    (truth,) = trace.runs
    assert truth.pushed_again_s is not None and truth.pushed_again_s > truth.release_s
    start = truth.release_index
    run = DecayRun(
        samples["t"][start:], samples["roll"][start:], samples["p"][start:], axis="roll", name="pushed"
    )
    end = find_free_end(run)
    assert end.kind == "excitation"
    assert end.t_s < truth.pushed_again_s - truth.release_s + 2 * 1.7  # caught within two periods of the push
    clean = hull_scenario(hull="swath", angle_deg=12.0, runs=1, seed=3).samples()[0]
    assert not np.allclose(clean["roll"][start:], samples["roll"][start:])
    assert math.isclose(abs(math.degrees(truth.angle0_rad)), 12.0, abs_tol=1.5)


def test_fault_scripts_are_parsed_or_refused_in_one_line() -> None:
    assert parse_fault_script("2:wrong-angle, 5:double-push") == {2: "wrong-angle", 5: "double-push"}
    assert scripted_run("wrong-angle", 10.0)["angle_deg"] == 15.0
    for bad in ("0:wrong-angle", "x:double-push", "3:sideways"):
        with pytest.raises(InputError, match="DECAY:FAULT"):
            parse_fault_script(bad)
    assert json.dumps(scripted_run(None, 8.0)) == '{"angle_deg": 8.0}'


def test_every_shipped_plan_has_valid_acceptance_tolerances() -> None:
    from tankdaq.config.plans import ACCEPTANCE_RANGES, list_campaign_plans, load_campaign_plan
    from tankdaq.errors import ConfigError
    from tankdaq.session.plan import plan_conditions

    for name in list_campaign_plans():
        plan = load_campaign_plan(name)
        Acceptance.from_plan(plan.acceptance, name)
        conditions = plan_conditions(plan)
        assert len(conditions) == len(plan.drafts) * len(plan.angles_deg)
        drafts = [c.draft for c in conditions]  # drafts grouped: each draft's conditions are contiguous
        assert drafts == sorted(drafts, key=[c.draft for c in conditions].index)
    assert load_campaign_plan("seed001-swath-roll").repeats == 3
    with pytest.raises(ConfigError, match="unknown key 'angle_tol'; did you mean 'angle_tolerance_deg'"):
        Acceptance.from_plan({"angle_tol": 1.0}, "plan x")
    assert {f.name for f in dataclasses.fields(Acceptance)} == set(ACCEPTANCE_RANGES)  # one table of ranges
