"""CSV decays: units, channels, the release cut, and one-line errors for bad files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from support.held_tilt import write_held_tilt_csv
from support.ident_helpers import KVLCC2_21338
from tankdaq.errors import BadIdentificationInput, InputError
from tankdaq.ident.inputs import read_decays
from tankdaq.physics.decay import simulate_decay


def test_units_channels_and_release_cut(tmp_path):
    (run,) = read_decays(write_held_tilt_csv(tmp_path / "d.csv"))
    assert run.t[0] == pytest.approx(2.0, abs=0.011)  # the end of the hold
    assert run.angle[0] == pytest.approx(math.radians(8.0), rel=1e-3)
    assert run.rate is not None and abs(run.rate[0]) < 0.05
    assert set(run.channels) == {"heave_m", "other_angle"}
    assert run.channels["other_angle"][0] == pytest.approx(math.radians(0.5))
    assert run.name == "d"


def test_the_store_reads_a_plain_csv_whole_and_ident_finds_its_release(tmp_path):
    from tankdaq.store.csv_import import FIND_RELEASES
    from tankdaq.store.inputs import read_runs

    path = write_held_tilt_csv(tmp_path / "d.csv")
    (record,) = read_runs(path)
    assert record.t[0] == 0.0 and record.meta[FIND_RELEASES] is True  # the store only reads
    (run,) = read_decays(path)
    assert run.t[0] > 1.9 and FIND_RELEASES not in run.meta


def test_keep_all_keeps_the_hold(tmp_path):
    (run,) = read_decays(write_held_tilt_csv(tmp_path / "d.csv"), keep_all=True)
    assert run.t[0] == 0.0


@pytest.mark.parametrize(
    ("content", "error", "message"),
    [
        (None, InputError, "no such file"),
        ("time_s,angle_deg\n0,1\n", BadIdentificationInput, "data rows"),
        (
            "time_s,angle_deg\n" + "".join(f"{i / 100},{'nan' if i == 5 else 1}\n" for i in range(50)),
            BadIdentificationInput,
            "NaN",
        ),
        (
            "time_s,angle_deg\n" + "".join(f"{i / 100},0.001\n" for i in range(50)),
            BadIdentificationInput,
            "not move",
        ),
        (
            "time_s,angle_deg\n" + "".join(f"{i / 100},{i / 10}\n" for i in range(50)),
            BadIdentificationInput,
            "no decay",
        ),
        ("t,angle_deg\n" + "".join(f"{i / 100},1\n" for i in range(50)), InputError, "no time column"),
        ("time_s,angle_deg\n" + "".join(f"{i / 100},x\n" for i in range(50)), InputError, "not a number"),
    ],
)
def test_bad_files_give_one_clear_error(tmp_path, content, error, message):
    path = tmp_path / "bad.csv"
    if content is not None:
        path.write_text(content)
    with pytest.raises(error, match=message):
        read_decays(path)


@pytest.mark.skipif(not KVLCC2_21338.is_file(), reason=f"KVLCC2 reference run not found at {KVLCC2_21338}")
def test_kvlcc2_starts_at_its_first_large_peak():
    (run,) = read_decays(KVLCC2_21338, time_col="time", angle_col="phi", rate_col=None, angle_unit="rad")
    # reference §7: driven from ~6.5 s to -10.4 deg at 8.08 s, free from there
    assert 8.0 < run.t[0] < 8.2
    assert math.degrees(run.angle[0]) == pytest.approx(-10.4, abs=0.1)
    assert run.rate is None and {"theta", "psi", "z"} <= set(run.channels)


def test_a_strongly_damped_decay_is_still_a_decay(tmp_path):
    """Seed 001 SWATH roll at 15 deg swings back only a few degrees: still a decay, cut at the release."""
    from tankdaq.config.hulls import load_hull

    c = load_hull("swath").simulation_model("roll").coefficients(1.0)
    t = np.arange(1700) / 100.0
    angle = np.full(t.size, math.radians(15.0))
    free = t >= 2.0
    angle[free], _ = simulate_decay(c, t[free] - 2.0, math.radians(15.0))
    assert np.max(-angle[free]) < 0.5 * math.radians(15.0), "the swing back is less than half the tilt"
    path = tmp_path / "damped.csv"
    np.savetxt(
        path, np.column_stack([t, np.degrees(angle)]), delimiter=",", header="time_s,angle_deg", comments=""
    )
    (run,) = read_decays(path, rate_col=None)
    assert abs(run.t[0] - 2.0) <= 0.011
    assert math.degrees(run.angle[0]) == pytest.approx(15.0, abs=0.01)
