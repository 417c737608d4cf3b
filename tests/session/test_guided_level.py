"""The guided session's level check measures exactly its stretch of still water, whatever arrives after."""

from __future__ import annotations

import numpy as np
import pytest

from tankdaq.device.driver import StreamBlock
from tankdaq.samples import empty_samples
from tankdaq.session.measure import LEVEL_S, LevelCheck


def _block(t_s: np.ndarray, roll_deg: np.ndarray) -> StreamBlock:
    samples = empty_samples(t_s.size)
    samples["t"] = t_s
    samples["roll"] = np.radians(roll_deg)
    return StreamBlock(samples, b"", 0.0)


def test_blocks_after_the_still_water_do_not_count() -> None:
    """A slow host stops the daemon late: the hand's tilt that arrives meanwhile is not "still water"."""
    heard: list[bool] = []
    level = LevelCheck("roll", on_full=lambda: heard.append(True))
    rng = np.random.default_rng(1)
    t = np.arange(0.0, LEVEL_S + 0.5, 0.01)
    still = 0.1 + rng.normal(0.0, 0.02, t.size)
    level.on_block(_block(t[: t.size // 2], still[: t.size // 2]), None)
    level.on_block(_block(t[t.size // 2 :], still[t.size // 2 :]), None)
    assert heard == [True]
    tilt = np.arange(t[-1] + 0.01, t[-1] + 5.0, 0.01)
    level.on_block(_block(tilt, np.linspace(0.1, 10.0, tilt.size)), None)  # arrives before the stop
    mean_deg, sd_deg = level.mean_sd_deg()
    kept = still[t <= LEVEL_S]
    assert mean_deg == pytest.approx(np.mean(kept), rel=1e-12)
    assert sd_deg == pytest.approx(np.std(kept), rel=1e-9)
    assert sd_deg < 0.05  # level: the tilt would have made it about 3 deg
