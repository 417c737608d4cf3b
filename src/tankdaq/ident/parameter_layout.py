"""Where each parameter of an output-error fit sits in the one parameter vector, by name.

The solver sees a flat vector; everything else (warm starts by name, fixed coefficients,
the report's shared and per-run values) asks the layout, so the order is decided once.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import BadIdentificationInput

#: The observation parameters shared by all runs, in layout order, with the setting that asks for each.
OBSERVATION_PARAMS: dict[str, str] = {
    "angle_gain_error": "fit_gain",
    "angle_lag_s": "fit_lag",
    "gyro_bias_rad_s": "fit_gyro_bias",
}
#: The unmeasured ringing's shared parameters, and its per-run amplitudes.
RING_PARAMS: tuple[str, str] = ("ring_omega_rad_s", "ring_decay_1_s")
RING_RUN_PARAMS: tuple[str, str] = ("ring_cos", "ring_sin")


class ParameterLayout:
    """Where each parameter sits in the vector: the shared ones, then each run's own.

    Shared: the dynamics terms, the input's coupling coefficients, the ringing's
    frequency and decay rate, the observation parameters. Per run: initial
    angle and rate, the angle offset, the ringing's amplitudes.
    """

    def __init__(
        self,
        dynamics: tuple[str, ...],
        couplings: tuple[str, ...],
        ringing: bool,
        observation: tuple[str, ...],
        offset: bool,
        n_runs: int,
    ) -> None:
        self.dynamics = dynamics
        self.couplings = couplings
        self.ringing = ringing
        self.shared = (*dynamics, *couplings, *(RING_PARAMS if ringing else ()), *observation)
        self.per_run = (
            "angle0",
            "rate0",
            *(("angle_offset_rad",) if offset else ()),
            *(RING_RUN_PARAMS if ringing else ()),
        )
        self.n_runs = n_runs
        self.n_shared = len(self.shared)
        self.size = self.n_shared + len(self.per_run) * n_runs
        self.names = [*self.shared] + [f"{name}[{r}]" for r in range(n_runs) for name in self.per_run]
        self._shared_index = {name: i for i, name in enumerate(self.shared)}

    @classmethod
    def for_model(
        cls,
        terms: Sequence[str],
        channels: Sequence[str],
        ringing: bool,
        observation: tuple[str, ...],
        offset: bool,
        n_runs: int,
    ) -> ParameterLayout:
        """The layout of a model's ``terms`` forced by the exogenous ``channels``: the ``ku`` term couples the
        one channel, else each channel gets its own ``k_<channel>``."""
        if "ku" in terms:
            if len(channels) != 1:
                raise BadIdentificationInput(
                    f"the ku term couples one exogenous channel; {len(channels)} given (exogenous=...)"
                )
            couplings: tuple[str, ...] = ("ku",)
        else:
            couplings = tuple(f"k_{ch}" for ch in channels)
        dynamics = tuple(t for t in terms if t != "ku")
        return cls(dynamics, couplings, ringing, observation, offset, n_runs)

    def index(self, name: str) -> int | None:
        """Position of a shared parameter (None when the model does not have it)."""
        return self._shared_index.get(name)

    def run_index(self, r: int, name: str) -> int | None:
        """Position of run r's own parameter (None when the model does not have it)."""
        return self.run_at(r, name) if name in self.per_run else None

    def at(self, name: str) -> int:
        """Position of a shared parameter the model has."""
        return self._shared_index[name]

    def run_at(self, r: int, name: str) -> int:
        """Position of run r's own parameter the model has."""
        return self.n_shared + len(self.per_run) * r + self.per_run.index(name)

    def run_slice(self, r: int) -> slice:
        start = self.n_shared + len(self.per_run) * r
        return slice(start, start + len(self.per_run))

    def value(self, params: np.ndarray, name: str, default: float = 0.0, run: int | None = None) -> float:
        """A parameter's value, shared or (with ``run``) of one run; ``default`` when the model lacks it."""
        i = self.index(name) if run is None else self.run_index(run, name)
        return default if i is None else float(params[i])

    def vector(
        self, shared: dict[str, float], per_run: list[dict[str, float]], default: dict[str, float]
    ) -> np.ndarray:
        """The vector from values by name: ``shared``, each run's own, ``default`` (else 0) where none is."""
        p0 = np.zeros(self.size)
        known = default | shared
        for i, name in enumerate(self.shared):
            p0[i] = known.get(name, 0.0)
        for r, values in enumerate(per_run):
            for name in self.per_run:
                p0[self.run_at(r, name)] = values.get(name, default.get(name, 0.0))
        return p0
