"""What the checks look at: a decay read back from its file with its final fit (``measure_decay``), and
the still water of the decay axis before a draft's first decay (``LevelCheck``, a sink of the pipeline).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from ..acquire.decay import LiveDecay
from ..acquire.pipeline import DecayOutcome
from ..acquire.sinks import Sink
from ..device.driver import StreamBlock
from ..ident.derived import b_eq
from ..samples import AXIS_FIELDS
from .checks import Measured

#: device seconds of still water the level check averages after a draft change
LEVEL_S = 2.0


def measure_decay(outcome: DecayOutcome, nominal_deg: float) -> Measured:
    """Read the decay back from its file (what is checked is what was stored) and its final fit."""
    from ..ident.free_decay import find_free_end
    from ..store.reader import read_decay_runs, read_recording

    assert outcome.path is not None
    recording = read_recording(outcome.path)
    release = next((e for e in recording.events if e.get("kind") == "release"), {})
    still = (release.get("data") or {}).get("still_water_deg", math.nan)
    measured = Measured(abs(outcome.angle_initial_deg), float(still), outcome.ended)
    runs = read_decay_runs(outcome.path)
    if runs:
        run = runs[0]
        rate = run.rate
        measured.max_rate_deg_s = (
            float(np.degrees(np.max(np.abs(rate)))) if rate is not None and rate.size else math.nan
        )
        end = find_free_end(run)
        measured.free_end, measured.free_end_reason = end.kind, end.reason
        if run.excluded is not None:
            measured.flagged_samples = int(np.count_nonzero(run.excluded))
            measured.flagged_why = str(run.meta.get("excluded_why", ""))
    fit = outcome.fit
    if fit is None:
        measured.fit_error = "; ".join(w for w in outcome.warnings if "fit" in w) or "no fit"
        return measured
    measured.half_cycles = fit.half_cycles
    measured.fit_warnings = [f.message for f in fit.findings if not f.about_data]  # clipping: checked below
    measured.r2_angle = fit.r2_angle
    measured.coefficients = dict(fit.coefficients)
    measured.natural_period_s = fit.natural_period_s
    measured.b_eq_per_s = b_eq(fit.coefficients, math.radians(nominal_deg))
    return measured


class LevelCheck(Sink):
    """A sink of the record pipeline: the still water of the decay axis over ``LEVEL_S`` of device
    time, read from every block; ``on_full`` is called once that much has arrived.

    A session's stream runs all along: ``arm()`` starts a measurement with the blocks read from then
    on (the ones read while the operator was still trimming the model are not the still water)."""

    def __init__(self, axis: str, on_full: Callable[[], None] = lambda: None) -> None:
        self.angle_field = AXIS_FIELDS[axis][0]
        self.on_full = on_full
        self._blocks: list[np.ndarray] = []
        self._since_host_t = -math.inf

    def arm(self) -> None:
        """Measure again, from the blocks read from now on."""
        self._blocks = []
        self._since_host_t = time.time()  # the clock of ``StreamBlock.host_t``

    def on_block(self, block: StreamBlock, decay: LiveDecay | None) -> None:
        if self.full or block.host_t < self._since_host_t:  # after it is full: not the still water measured
            return
        if block.samples.size:
            self._blocks.append(block.samples)
        if self.full:
            self.on_full()

    @property
    def full(self) -> bool:
        return bool(self._blocks) and float(self._blocks[-1]["t"][-1] - self._blocks[0]["t"][0]) >= LEVEL_S

    def mean_sd_deg(self) -> tuple[float, float]:
        """Mean and spread of the angle over exactly the first ``LEVEL_S`` of device time: never the
        motion after it (a hand tilting the model while a slow host stops the daemon)."""
        samples = np.concatenate(self._blocks)
        first = samples[samples["t"] <= samples["t"][0] + LEVEL_S]
        angle = np.degrees(first[self.angle_field])
        return float(angle.mean()), float(angle.std())
