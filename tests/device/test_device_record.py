"""``record`` against the simulated MTi in each state a lab leaves a device in (real pty, real MCAP).

Every case connects, records one decay and finds its release within one sample of the truth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from support.record_settings import sim_record_settings
from tankdaq.acquire.daemon import RecordDaemon
from tankdaq.config.hulls import hull_scenario
from tankdaq.device.simulator import Behaviour, DeviceIdentity, Faults, SimulatedMTi
from tankdaq.physics.scenario import DecayScenario
from tankdaq.store.reader import read_recording
from tankdaq.xsens.constants import MID

TICKS_PER_S = 10_000
#: Device clock speed-up: the recorder (live fit included) keeps up with 600 frames/s on a loaded
#: 2-core machine; 400 Hz runs at a third of it.
SPEED = 6.0


def _record(tmp_path: Path, sim: SimulatedMTi, port: str, rate_hz: float, baud: int | None = None):
    settings = sim_record_settings(
        tmp_path, port=port, rate_hz=rate_hz, baud=baud, runs=1, reconnect_timeout_s=20.0
    )
    (outcome,) = RecordDaemon(settings).run()
    recording = read_recording(outcome.path)
    release = next(e for e in recording.events if e["kind"] == "release")
    first_free_ticks = round(release["data"]["first_free_sample_t_s"] * TICKS_PER_S)
    ticks = recording.samples["ticks"]
    releases = [r for r in sim.truth if r.kind == "release"]
    truth = min(releases, key=lambda r: abs(r.release_ticks - first_free_ticks))
    true_first = int(ticks[np.searchsorted(ticks, truth.release_ticks)])
    assert abs(first_free_ticks - true_first) <= TICKS_PER_S / rate_hz, (first_free_ticks, true_first)
    return recording


def _scenario(rate_hz: float, release_after_s: float) -> DecayScenario:
    return hull_scenario(rate_hz=rate_hz, runs=2, seed=5, release_after_s=release_after_s, decay_s=12.0)


@pytest.mark.parametrize(
    ("behaviour", "release_after_s"),
    [
        (Behaviour(stuck=True, boot_s=1.7), 45.0),  # GoToConfig ignored until Reset; acked ~1.7 s later
        (Behaviour(flash_write_s=0.5), 25.0),  # SetOutputConfiguration acked after half a second
    ],
    ids=["stuck-until-reset", "slow-flash-writes"],
)
@pytest.mark.slow
def test_record_connects_to_a_difficult_device(
    tmp_path: Path, behaviour: Behaviour, release_after_s: float
) -> None:
    with SimulatedMTi(_scenario(100, release_after_s), speed=SPEED, behaviour=behaviour) as sim:
        recording = _record(tmp_path, sim, sim.link, 100)
    assert recording.metadata["baud"] == "115200" and recording.metadata["baud_changed"] == "false"


@pytest.mark.slow
def test_record_400_hz_at_921600_from_a_device_at_115200_has_no_gaps(tmp_path: Path) -> None:
    with SimulatedMTi(_scenario(400, 12.0), speed=SPEED / 3, baud=115200) as sim:  # 400 Hz: a slower clock
        recording = _record(tmp_path, sim, sim.link, 400, baud=921600)
        assert sim.baud == 921600
    meta = recording.metadata
    assert (meta["baud"], meta["baud_changed"], meta["baud_before"]) == ("921600", "true", "115200")
    assert float(meta["measured_sample_rate_hz"]) == pytest.approx(400, rel=1e-6)
    steps = np.diff(recording.samples["counter"].astype(np.int64)) % 65536
    assert np.all(steps == 1) and meta["link_gaps"] == "0" and meta["link_lost"] == "0"


@pytest.mark.slow
def test_record_moves_a_600_series_device_with_port_config(tmp_path: Path) -> None:
    with SimulatedMTi(_scenario(100, 25.0), speed=SPEED, identity=DeviceIdentity.mti_630()) as sim:
        recording = _record(tmp_path, sim, sim.link, 100, baud=921600)
        assert sim.baud == 921600 and MID.SET_PORT_CONFIG in sim.commands_seen
    meta = recording.metadata
    assert (meta["product_code"], meta["baud"], meta["baud_before"]) == ("MTi-630-2A8G4", "921600", "115200")


@pytest.mark.slow
def test_record_follows_a_replug_under_a_new_name_by_usb_serial(tmp_path: Path) -> None:
    unplug = Faults(unplug_at_s=15.0, replug_after_s=3.0)  # before the first release, at 25 s
    with SimulatedMTi(_scenario(100, 25.0), speed=SPEED, faults=unplug) as sim:
        first_name = sim.port
        _record(tmp_path, sim, first_name, 100)  # by its /dev/pts name, which does not come back
        assert sim.port != first_name
