"""Goodness of an output-error fit from its predictions: residuals, R², NRMSE, residual whiteness.

Pure functions of the runs and the predicted outputs, apart from the estimator so the numbers a
fit reports are computed in one visible place.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..records import DecayRun
from .one_step import rms
from .signals import white_noise_level
from .uncertainty import residual_whiteness, whiteness_warning


@dataclass
class ResidualSummary:
    """The fitted outputs and residuals per run, and the numbers made of them."""

    fitted: list[dict[str, Any]]  # per run {"angle", "rate"}
    residuals: list[dict[str, Any]]  # per run {"angle", "rate" (None without a measured rate)}
    r2_angle: float
    nrmse: float  # angle RMS error over the angle's peak-to-peak range
    blocks: list[np.ndarray]  # the kept residuals of each run and output, for the BIC
    block_sigmas: list[float]  # the noise level weighting each block


def summarize_residuals(
    runs: Sequence[DecayRun],
    predictions: Sequence[dict[str, Any]],
    kept: Sequence[np.ndarray],
    has_rate: Sequence[bool],
    sigmas: Sequence[dict[str, float]],
) -> ResidualSummary:
    """Residuals of ``predictions`` against ``runs``; only the ``kept`` samples count in the numbers."""
    fitted: list[dict[str, Any]] = []
    residuals: list[dict[str, Any]] = []
    ss_res = ss_tot = 0.0
    blocks_res: list[np.ndarray] = []
    blocks_sigma: list[float] = []
    for r, (run, pred) in enumerate(zip(runs, predictions, strict=True)):
        resid_angle = run.angle - pred["angle"]
        resid_rate = run.rate - pred["rate"] if has_rate[r] else None
        fitted.append({"angle": pred["angle"], "rate": pred["rate"]})
        residuals.append({"angle": resid_angle, "rate": resid_rate})
        keep = kept[r]
        ss_res += float(resid_angle[keep] @ resid_angle[keep])
        ss_tot += float(np.sum((run.angle[keep] - run.angle[keep].mean()) ** 2))
        for output, resid in (("angle", resid_angle), ("rate", resid_rate)):
            if resid is not None:
                blocks_res.append(resid[keep])
                blocks_sigma.append(sigmas[r][output])
    all_angle = np.concatenate([run.angle[keep] for run, keep in zip(runs, kept, strict=True)])
    return ResidualSummary(
        fitted=fitted,
        residuals=residuals,
        r2_angle=1.0 - ss_res / ss_tot,
        nrmse=math.sqrt(ss_res / all_angle.size) / float(np.ptp(all_angle)),
        blocks=blocks_res,
        block_sigmas=blocks_sigma,
    )


def whiteness_warnings(
    runs: Sequence[DecayRun], residuals: Sequence[dict[str, Any]], kept: Sequence[np.ndarray]
) -> list[str]:
    """One warning per run and output whose kept residuals are not white (the model misses something)."""
    warnings = []
    for run, resid, keep in zip(runs, residuals, kept, strict=True):
        for output in ("angle", "rate"):
            if resid[output] is not None:
                warning = whiteness_warning(run.name, output, *residual_whiteness(resid[output][keep]))
                if warning:
                    warnings.append(warning)
    return warnings


def initial_noise_levels(run: DecayRun, has_rate: bool) -> dict[str, float]:
    """Noise levels from third differences, floored so a clean record does not get infinite weight."""
    floor_angle = 1e-4 * float(np.ptp(run.angle))
    sig = {"angle": max(white_noise_level(run.angle), floor_angle)}
    if has_rate and run.rate is not None:
        sig["rate"] = max(white_noise_level(run.rate), 1e-4 * float(np.ptp(run.rate)))
    return sig


def angle_r2(
    runs: Sequence[DecayRun], predictions: Sequence[dict[str, Any]], kept: Sequence[np.ndarray]
) -> float:
    """R² of the predicted angle over the kept samples of all runs (the fallback start's test)."""
    ss_res = ss_tot = 0.0
    for run, pred, keep in zip(runs, predictions, kept, strict=True):
        ss_res += float(np.sum((run.angle - pred["angle"])[keep] ** 2))
        ss_tot += float(np.sum((run.angle[keep] - run.angle[keep].mean()) ** 2))
    return 1.0 - ss_res / ss_tot


def residual_noise_levels(
    runs: Sequence[DecayRun],
    predictions: Sequence[dict[str, Any]],
    kept: Sequence[np.ndarray],
    has_rate: Sequence[bool],
) -> list[dict[str, float]]:
    """Per run the RMS residual of each output: the weights of the refit after the first solve."""
    out = []
    for r, (run, pred) in enumerate(zip(runs, predictions, strict=True)):
        sig = {"angle": max(rms((run.angle - pred["angle"])[kept[r]]), 1e-12)}
        if has_rate[r]:
            sig["rate"] = max(rms((run.rate - pred["rate"])[kept[r]]), 1e-12)
        out.append(sig)
    return out
