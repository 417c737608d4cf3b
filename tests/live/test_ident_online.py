"""Live refits: published at half-cycles, converging to the offline answer."""

from __future__ import annotations

import numpy as np
import pytest

from support.ident_helpers import synthetic_run, truth_for
from tankdaq.errors import IdentificationError
from tankdaq.ident.output_error import OutputErrorFit
from tankdaq.live.identifier import OnlineIdentifier


@pytest.mark.slow
def test_online_refits_converge_to_the_offline_fit():
    truth = truth_for(("b1", "b2", "c1", "c3"))
    run = synthetic_run(truth, seed=21, angle0=0.25)
    published = []
    online = OnlineIdentifier("b1,b2,c1,c3", callback=published.append, horizon_s=1.0)
    for start in range(0, run.t.size, 10):  # 10-sample packets, as the driver delivers them
        online.update(run.t[start : start + 10], run.angle[start : start + 10], run.rate[start : start + 10])
    final = online.finish()
    offline = OutputErrorFit("b1,b2,c1,c3").fit([run])

    assert len(published) >= 10  # about two refits per period over 15 s
    assert [r.half_cycles for r in published[:-1]] == sorted({r.half_cycles for r in published[:-1]})
    for k in truth:
        assert final.coefficients[k] == pytest.approx(offline.coefficients_[k], abs=0.1 * offline.std_[k])
    # intervals shrink as the decay goes on; the last fit holds the truth within 3.29 std
    assert published[-1].std["c1"] < published[0].std["c1"]
    for k, value in truth.items():
        assert abs(final.coefficients[k] - value) < 3.29 * final.std[k]
    assert published[-1].predicted_t[-1] == pytest.approx(run.t[-1] + 1.0, abs=0.011)


def test_nothing_is_fitted_before_enough_half_cycles_and_a_short_record_is_refused():
    truth = truth_for(("b1", "c1"))
    run = synthetic_run(truth, seed=22)
    online = OnlineIdentifier("ittc-linear")
    assert online.update(run.t[:30], run.angle[:30], run.rate[:30]) is None
    assert online.results_ == []
    with pytest.raises(IdentificationError):
        online.finish()


@pytest.mark.slow
def test_a_settled_noisy_record_does_not_trigger_refits():
    """After the motion dies out the gyro only shows noise: its zero crossings are not half-cycles."""
    truth = {"b1": 1.5, "c1": 14.0}  # heavily damped: settled within ~8 s
    run = synthetic_run(truth, seed=23, duration_s=20.0)
    online = OnlineIdentifier("ittc-linear")
    settled_from = np.searchsorted(run.t, 10.0)
    refits_after = 0
    for start in range(0, run.t.size, 10):
        result = online.update(
            run.t[start : start + 10], run.angle[start : start + 10], run.rate[start : start + 10]
        )
        refits_after += result is not None and start >= settled_from
    assert len(online.results_) >= 3
    assert refits_after <= 1
