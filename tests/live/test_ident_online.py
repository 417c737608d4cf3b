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


@pytest.mark.slow
def test_the_final_fit_is_the_samples_up_to_the_end_whatever_the_refits_and_reads_were():
    """Two identifiers fed the same decay in different packets (so their refits fall elsewhere and start
    from other answers), one of them fed a second more past the end the detector decided: the final fits
    are equal to the last bit, and equal to a cold ``auto`` identifier's fed all at once."""
    truth = truth_for(("b1", "b2", "c1", "c3"))
    run = synthetic_run(truth, seed=24, angle0=0.25)
    end_t = float(run.t[int(run.t.size * 0.8)])
    finals = []
    for packet, past_end_s in ((7, 0.0), (53, 1.0)):
        online = OnlineIdentifier("auto")
        fed = run.t <= end_t + past_end_s
        for start in range(0, int(fed.sum()), packet):
            part = slice(start, min(start + packet, int(fed.sum())))
            online.update(run.t[part], run.angle[part], run.rate[part])
        assert online.results_  # refits ran, from starts of their own
        finals.append(online.finish(until_t=end_t))
    whole = OnlineIdentifier("auto")
    kept = run.t <= end_t
    whole.update(run.t[kept], run.angle[kept], run.rate[kept])
    finals.append(whole.finish())
    for other in finals[1:]:
        assert other.coefficients == finals[0].coefficients
        assert other.ci95 == finals[0].ci95 and other.n_samples == finals[0].n_samples
