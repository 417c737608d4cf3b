"""Synthetic campaigns with known truth (``tankdaq simulate-campaign``, the tests and the benches): one
decay per hull x draft x angle from the hulls' ``[simulation]`` coefficients, written as CSV or as a tankdaq
recording, held tilt, release and all.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.hulls import format_draft, load_hull
from ..errors import InputError
from ..physics.decay import simulate_decay
from ..samples import AXIS_FIELDS, empty_samples


@dataclass(frozen=True)
class SimulatedTest:
    """How each simulated decay is made: hold the tilt, release at rest, sample like an MTi-G.

    Noise: about the MTi-G's (0.02 deg on the angle, 0.1 deg/s on the gyro at 100 Hz).
    """

    duration_s: float = 5.0
    hold_s: float = 0.5
    rate_hz: float = 100.0
    angle_noise_rad: float = 3e-4
    rate_noise_rad_s: float = 2e-3

    @property
    def release_index(self) -> int:
        return round(self.hold_s * self.rate_hz)


def simulated_decay(
    coefficients: dict[str, float], angle_deg: float, test: SimulatedTest, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, angle, rate): a held tilt, then the free decay from rest, with white sensor noise."""
    dt = 1.0 / test.rate_hz
    t = np.arange(0.0, test.duration_s, dt)
    n_hold = test.release_index
    angle = np.full(t.size, math.radians(angle_deg))
    rate = np.zeros(t.size)
    angle[n_hold:], rate[n_hold:] = simulate_decay(coefficients, t[n_hold:], math.radians(angle_deg))
    return (
        t,
        angle + rng.normal(0.0, test.angle_noise_rad, t.size),
        rate + rng.normal(0.0, test.rate_noise_rad_s, t.size),
    )


def write_simulated_campaign(
    folder: Path,
    hulls: Sequence[str],
    axis: str,
    drafts: Sequence[float],
    angles_deg: Sequence[float],
    file_format: str = "csv",
    test: SimulatedTest = SimulatedTest(),
    seed: int = 0,
) -> list[Path]:
    """One decay file per hull x draft x angle, from the coefficients in configs/hulls.

    CSV: columns time_s, angle_deg, rate_deg_s from the release on, labels in the file name. MCAP: a
    tankdaq recording (the held tilt, the samples and a release event) with the labels in its metadata.
    """
    if file_format not in ("csv", "mcap"):
        raise InputError(f"format {file_format!r} not understood: use csv or mcap")
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    written = []
    for hull_spec in hulls:
        hull = load_hull(hull_spec)  # a name or a .toml path; files are labelled with the hull's name
        hull_name, model = hull.name, hull.simulation_model(axis)
        for draft in drafts:
            coefficients = model.coefficients(draft)
            for angle_deg in angles_deg:
                t, angle, rate = simulated_decay(coefficients, angle_deg, test, rng)
                stem = f"{hull_name}_{format_draft(draft)}_{axis}_{angle_deg:g}deg_run01"
                if file_format == "csv":
                    path = folder / f"{stem}.csv"
                    table = np.column_stack([t, np.degrees(angle), np.degrees(rate)])[test.release_index :]
                    np.savetxt(path, table, delimiter=",", header="time_s,angle_deg,rate_deg_s", comments="")
                else:
                    labels = (hull_name, axis, draft, angle_deg)
                    path = write_simulated_recording(folder / f"{stem}.mcap", labels, t, angle, rate, test)
                written.append(path)
    return written


def write_simulated_recording(
    path: Path,
    labels: tuple[str, str, float, float],
    t: np.ndarray,
    angle: np.ndarray,
    rate: np.ndarray,
    test: SimulatedTest,
    extra: Mapping[str, object] | None = None,
) -> Path:
    """A tankdaq recording of a simulated decay (a held tilt, the samples, a release event), labelled
    (hull, axis, draft, nominal angle) in its metadata; ``extra``: more run metadata (how it ended)."""
    from ..store.writer import RecordingWriter

    hull, axis, draft, angle_deg = labels
    samples = empty_samples(t.size)
    samples["t"] = t
    samples["ticks"] = np.round(t * 1e4).astype(np.int64)
    samples["counter"] = np.arange(t.size) % 65536
    angle_field, rate_field = AXIS_FIELDS[axis]
    for name in ("roll", "pitch", "yaw", "p", "q", "r", "ax", "ay"):
        samples[name] = 0.0
    samples["az"] = 9.81
    samples[angle_field] = angle
    samples[rate_field] = rate
    metadata = {
        "hull": hull,
        "axis": axis,
        "draft": format_draft(draft),
        "angle_nominal_deg": angle_deg,
        "sample_rate_hz": test.rate_hz,
        "note": "simulated from configs/hulls",
        **(extra or {}),
    }
    with RecordingWriter(path, metadata, {"simulated": True, "hull": hull}) as writer:
        writer.write_samples(samples)
        writer.write_event("release", "simulated release", t_s=float(t[test.release_index]))
    return writer.path
