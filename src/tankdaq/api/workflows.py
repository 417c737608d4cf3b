"""``tankdaq.simulate``: decay tests without hardware (``tankdaq.campaign`` is ``api.campaigns``,
``tankdaq.diagnose`` ``api.diagnosis``).

``simulate`` plays a hull's scripted decay test (``config.hull_scenario``: the simulator's physics and
sensor) into real recording files, one per decay as ``tankdaq record`` writes them.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import validation
from . import arguments
from .recording import Recording, read

if TYPE_CHECKING:
    import numpy as np

    from ..physics.truth import RunTruth


def simulate(
    out_dir: str | Path = "recordings/simulated",
    *,
    hull: str | Path = "swath",
    draft: float | str = 1.0,
    axis: str = "roll",
    angle_deg: float = 8.0,
    runs: int = 1,
    rate_hz: float = 100.0,
    seed: int | None = None,
    decay_s: float = 25.0,
) -> list[Recording]:
    """Simulated decay tests without hardware: the hull's scripted test (still water, a tilt by hand, the
    release, the free decay; MTi-G noise) written as tankdaq recordings into ``out_dir``, one per decay,
    and read back. The truth (release, coefficients) is in each file's run configuration; ``seed``
    None draws a new one (every call its own decays), which each file's metadata says (``sim_seed``):
    that seed plays the same test again.

    >>> (rec,) = tankdaq.simulate("sim", hull="swath", angle_deg=8.0, seed=1)  # doctest: +SKIP
    >>> tankdaq.identify(rec).coefficients  # doctest: +SKIP
    """
    from ..config.hulls import hull_scenario, load_hull
    from ..physics.scenario import fresh_seed
    from ..physics.truth import RunKind

    folder = validation.output_dir(
        arguments.path(out_dir, "out_dir", "a folder (str or pathlib.Path)"), "out_dir"
    )
    hull_name = str(arguments.path(hull, "hull", "a hull's name or a .toml path"))
    axis = validation.decay_axis(arguments.text(axis, "axis", "roll or pitch"), option="axis")
    factor = validation.draft_factor(arguments.draft(draft))
    angle_deg = arguments.number(angle_deg, "angle_deg", unit="degrees")
    runs = arguments.whole(runs, "runs", 1, 100)
    rate_hz = arguments.number(rate_hz, "rate_hz", unit="Hz")
    seed = fresh_seed(None if seed is None else arguments.whole(seed, "seed", 0, 2**63 - 1))
    decay_s = arguments.number(decay_s, "decay_s", 1.0, 3600.0, unit="s")
    loaded = load_hull(hull_name)
    validation.hull_draft(loaded, factor, axis)
    scenario = hull_scenario(
        loaded,
        factor,
        axis,
        angle_deg=validation.release_angle_deg(angle_deg, option="angle_deg"),
        rate_hz=validation.output_rate_hz(rate_hz, option="rate_hz"),
        runs=runs,
        seed=seed,
        decay_s=decay_s,
    )
    samples, trace = scenario.samples()
    folder.mkdir(parents=True, exist_ok=True)
    paths = [
        _write_decay(folder, loaded, factor, angle_deg, seed, samples, truth, trace.start_ticks)
        for truth in trace.runs
        if truth.kind == RunKind.RELEASE
    ]
    return [read(path) for path in paths]


def _write_decay(
    folder: Path,
    hull: Any,
    draft: float,
    angle_deg: float,
    seed: int,
    samples: np.ndarray,
    truth: RunTruth,
    start_ticks: int,
) -> Path:
    """One decay's samples (from the tilt to the end of its run) as a recording with its release event
    and the seed that played it."""
    from ..physics.truth import TICKS_PER_S
    from ..store.naming import recording_name
    from ..store.writer import RecordingWriter, describe_run

    origin_s = start_ticks / TICKS_PER_S
    part = samples[(samples["t"] >= origin_s + truth.tilt_start_s) & (samples["t"] < origin_s + truth.end_s)]
    rate_hz = float(1.0 / (part["t"][1] - part["t"][0]))
    metadata = describe_run(truth.axis, angle_deg, hull, draft, rate_hz, operator="tankdaq.simulate")
    metadata["note"] = "simulated (tankdaq.simulate): the truth is in the run configuration"
    metadata["sim_seed"] = seed
    name = recording_name(hull.name, draft, truth.axis, angle_deg, truth.run + 1)
    with RecordingWriter(folder / name, metadata, {"simulated": True, "truth": truth.to_json()}) as writer:
        writer.write_samples(part)
        release_s = origin_s + float(truth.release_s or 0.0)
        writer.write_event("release", "simulated release", t_s=release_s)
    return writer.path
