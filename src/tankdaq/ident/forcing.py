"""The input u(t) that forces an output-error model, and its partials in the parameter vector.

Measured channels (each with its coupling coefficient) and the unmeasured ringing enter the
decay equation as ``ku*u``; the sensitivity kernel needs du/dparameter for every parameter of
u, so the forcing is built here once, from the layout, for the solver and the predictions alike.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .parameter_layout import RING_PARAMS, RING_RUN_PARAMS, ParameterLayout


@dataclass
class Forcing:
    """The input u(t) of one run at given parameters, and its partials in the layout's columns."""

    u: np.ndarray
    partials: np.ndarray  # (n, m)
    columns: list[int]  # layout column of each partial


def input_forcing(
    layout: ParameterLayout, params: np.ndarray, r: int, t: np.ndarray, channels: Sequence[np.ndarray]
) -> Forcing:
    """u(t) = sum_c k_c u_c(t) + exp(-l s)(p cos ws + q sin ws), s = t - t[0], and du/dparameter."""
    u = np.zeros_like(t)
    partials: list[np.ndarray] = []
    columns: list[int] = []
    for name, series in zip(layout.couplings, channels, strict=True):
        i = layout.at(name)
        u = u + params[i] * series
        partials.append(series)
        columns.append(i)
    if layout.ringing:
        omega_i, decay_i = (layout.at(n) for n in RING_PARAMS)
        cos_i, sin_i = (layout.run_at(r, n) for n in RING_RUN_PARAMS)
        since = t - t[0]
        envelope = np.exp(-params[decay_i] * since)
        cos, sin = envelope * np.cos(params[omega_i] * since), envelope * np.sin(params[omega_i] * since)
        ring = params[cos_i] * cos + params[sin_i] * sin
        u = u + ring
        partials += [since * (params[sin_i] * cos - params[cos_i] * sin), -since * ring, cos, sin]
        columns += [omega_i, decay_i, cos_i, sin_i]
    stacked = np.stack(partials, axis=1) if partials else np.zeros((t.size, 0))
    return Forcing(u, np.ascontiguousarray(stacked), columns)
