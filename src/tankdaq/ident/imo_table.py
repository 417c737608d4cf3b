"""The IMO table: Bertin's N against the mean amplitude φm from decays at several initial angles
(MSC.1/Circ.1200 §4.6.1.1; its example: four decays, N from 10° to 25°), and what the decays do not reach.

Each fitted campaign group (one initial angle, its repeats fitted jointly) covers the mean amplitudes
of successive peaks its decays pass through, φm = (φn + φn+1) / 2 from the release angle down to
0.5° (where ITTC stops a decay); its fit gives N(φ) there (``derived.bertin_n_per_deg``, the model's
curve through the measured points). At each asked amplitude the table gives N from the groups that
cover it: their mean, with the spread between them (the standard deviation of their mean) where two
or more do, else the one fit's own standard deviation; each value says which (``interval_labels``).

An amplitude no decay reaches needs another initial angle: a decay from φ0 first passes the mean
amplitude φ0 − Δφ/2, Bertin's decrement per half cycle being Δφ = N φm² (deg), so the decay passes
φm from φ0 = φm + N(φm) φm² / 2 on, N from the fit of the largest initial angle (its model carried
beyond its data: an estimate, said as one). An amplitude below every decay's end needs decays that
run longer. The table is data; the API makes it a DataFrame (``api.campaigns``).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..config.hulls import format_draft
from ..config.rules import MAX_RELEASE_ANGLE_DEG
from ..records import DecayRun
from .derived import amplitude_table
from .interval_labels import ANGLES_STD, FIT_STD, IntervalLabel
from .signals import half_cycle_peaks

#: The amplitudes MSC.1/Circ.1200's example reports N at (deg).
IMO_AMPLITUDES_DEG = (10.0, 15.0, 20.0, 25.0)
#: The keys of a measured point in ``--json`` (``ImoTable.points``).
POINT_KEYS = ("initial_angle_deg", "mean_amplitude_deg", "decrement_deg")
#: Peaks below this are not a tested amplitude (ITTC stops a decay at 0.5°), or 20 % of the largest.
FLOOR_DEG = 0.5


class _Condition(Protocol):
    """A group's condition (``campaign.GroupKey``)."""

    @property
    def hull(self) -> str: ...
    @property
    def axis(self) -> str: ...
    @property
    def draft(self) -> float: ...
    @property
    def angle_deg(self) -> float: ...


def initial_angle_deg(runs: Sequence[DecayRun], offsets: Sequence[float]) -> float:
    """The measured initial angle of decays (deg): the mean over them of the largest |angle| of the first
    half cycle, about their equilibrium (``offsets``), not the nominal angle they were asked at."""
    return float(np.mean([_peaks(run, offset)[0] for run, offset in zip(runs, offsets, strict=True)]))


def _peaks(run: DecayRun, offset: float) -> np.ndarray:
    """|angle| at the release's half cycle and at every complete half cycle after it (deg)."""
    y = np.degrees(run.angle - offset)
    later = half_cycle_peaks(y)
    first = float(np.max(np.abs(y[: later[0]] if later.size else y)))
    return np.concatenate([[first], np.abs(y[later])])


@dataclass(frozen=True, eq=False)  # holds an array
class DecayCover:
    """What one fitted group gives the IMO table: its condition, its measured initial angle, the mean
    amplitudes and decrements per half cycle of its decays (deg) and its fit (per unit inertia, SI)."""

    hull: str
    axis: str
    draft: float
    nominal_deg: float
    initial_deg: float
    mean_amplitude_deg: tuple[float, ...]
    decrement_deg: tuple[float, ...]
    coefficients: dict[str, float]
    covariance: np.ndarray

    @property
    def condition(self) -> tuple[str, str, float]:
        return self.hull, self.axis, self.draft

    def covers(self, amplitude_deg: float) -> bool:
        """Whether its decays pass through the mean amplitude ``amplitude_deg``."""
        amplitudes = self.mean_amplitude_deg
        return bool(amplitudes) and min(amplitudes) <= amplitude_deg <= max(amplitudes)

    def bertin_n(self, amplitude_deg: float) -> tuple[float, float]:
        """Its fit's N (1/deg) and the fit's standard deviation of it at ``amplitude_deg``."""
        (point,) = amplitude_table(self.coefficients, self.covariance, [amplitude_deg])
        return point.bertin_n_per_deg, point.bertin_n_std


def decay_cover(key: _Condition, runs: Sequence[DecayRun], fit: Any) -> DecayCover:
    """A fitted group's ``DecayCover`` (``key`` a ``campaign.GroupKey``, ``fit`` its ``OutputErrorFit``)."""
    means: list[float] = []
    drops: list[float] = []
    for run, offset in zip(runs, fit.offsets_, strict=True):
        peaks = _peaks(run, offset)
        lost = np.flatnonzero(peaks < min(FLOOR_DEG, 0.2 * peaks[0]))  # the decay ends in the noise
        peaks = peaks[: lost[0]] if lost.size else peaks
        means += (0.5 * (peaks[:-1] + peaks[1:])).tolist()
        drops += (peaks[:-1] - peaks[1:]).tolist()
    return DecayCover(
        key.hull, key.axis, key.draft, key.angle_deg, initial_angle_deg(runs, fit.offsets_),
        tuple(means), tuple(drops), dict(fit.coefficients_), np.asarray(fit.covariance_),
    )  # fmt: skip


@dataclass(frozen=True)
class ImoRow:
    """N at one asked amplitude: its value and uncertainty (labelled), the measured initial angles of the
    decays that cover it; where none does, NaN and the initial angle estimated to reach it."""

    amplitude_deg: float
    bertin_n_per_deg: float
    uncertainty_per_deg: float
    interval: IntervalLabel | None
    initial_angles_deg: tuple[float, ...]
    needed_initial_deg: float | None = None

    @property
    def reached(self) -> bool:
        return bool(self.initial_angles_deg)

    def as_dict(self) -> dict[str, Any]:
        """One row of the table (``--json``, the API's DataFrame): angles in deg, N in 1/deg."""
        return {
            "amplitude_deg": self.amplitude_deg,
            "bertin_n_per_deg": self.bertin_n_per_deg,
            "bertin_n_std": self.uncertainty_per_deg,
            "interval": self.interval.text if self.interval is not None else "",
            "reached": self.reached,
            "initial_angles_deg": list(self.initial_angles_deg),
            "needed_initial_deg": self.needed_initial_deg,
        }


@dataclass(frozen=True)
class ImoTable:
    """Bertin's N at the asked amplitudes for one hull, axis and draft, from its groups' decays."""

    hull: str
    axis: str
    draft: float
    rows: tuple[ImoRow, ...]
    covered_deg: tuple[float, float]  # the mean amplitudes the decays pass through, lowest and highest
    initial_angles_deg: tuple[float, ...]  # measured, one per group
    points: tuple[tuple[float, float, float], ...] = ()  # measured: initial angle, φm, decrement (deg)

    @property
    def label(self) -> str:
        return f"{self.hull} {self.axis} {format_draft(self.draft)}"

    @property
    def missing(self) -> list[ImoRow]:
        return [row for row in self.rows if not row.reached]

    def records(self) -> list[dict[str, Any]]:
        """The rows with their condition, one dict each (a DataFrame's rows)."""
        condition = {"hull": self.hull, "axis": self.axis, "draft": format_draft(self.draft)}
        return [condition | row.as_dict() for row in self.rows]

    def as_dict(self) -> dict[str, Any]:
        """``--json``'s object of this table, with the measured points: mean angle against decrement per half
        cycle, as MSC.1/Circ.1200's example reports them beside N."""
        return {
            "hull": self.hull, "axis": self.axis, "draft": format_draft(self.draft),
            "covered_deg": list(self.covered_deg), "initial_angles_deg": list(self.initial_angles_deg),
            "rows": [row.as_dict() for row in self.rows], "missing": self.missing_line(),
            "points": [dict(zip(POINT_KEYS, point, strict=True)) for point in self.points],
        }  # fmt: skip

    def missing_line(self) -> str:
        """Which asked amplitudes the decays do not reach, and which initial angles would reach them."""
        low, high = self.covered_deg
        parts = []
        for row in self.missing:
            if row.amplitude_deg < low:
                parts.append(f"{row.amplitude_deg:g}° (the decays end at {low:.1f}°: record them longer)")
            elif row.needed_initial_deg is not None and row.needed_initial_deg > MAX_RELEASE_ANGLE_DEG:
                parts.append(
                    f"{row.amplitude_deg:g}° (needs an initial angle of about {row.needed_initial_deg:.0f}°, "
                    f"beyond any release ({MAX_RELEASE_ANGLE_DEG:g}°): decays cannot give N there)"
                )
            elif row.needed_initial_deg is not None:
                parts.append(
                    f"{row.amplitude_deg:g}° (needs an initial angle of about {row.needed_initial_deg:.1f}°)"
                )
            else:
                parts.append(
                    f"{row.amplitude_deg:g}° (between the decays' bands: add an initial angle near it)"
                )
        if not parts:
            return ""
        return (
            f"not reached: {', '.join(parts)}; the decays pass φm {low:.1f}°–{high:.1f}° "
            f"(initial angles {', '.join(f'{a:.1f}' for a in self.initial_angles_deg)}°, measured); "
            "initial angles estimated from the largest one's fit, Δφ = N φm²"
        )

    def lines(self) -> list[str]:
        """The table as Markdown, with the line on what is not reached."""
        out = [
            f"Bertin's N (MSC.1/Circ.1200), {self.label}: N against mean amplitude φm",
            "",
            "| φm deg | N 1/deg | ± | interval | decays from (deg, measured) |",
            "|---|---|---|---|---|",
        ]
        for row in self.rows:
            if row.reached:
                angles = ", ".join(f"{a:.1f}" for a in row.initial_angles_deg)
                out.append(
                    f"| {row.amplitude_deg:g} | {row.bertin_n_per_deg:.4g} | {row.uncertainty_per_deg:.2g} "
                    f"| {row.interval} | {angles} |"
                )
            else:
                out.append(f"| {row.amplitude_deg:g} | not reached | | | |")
        missing = self.missing_line()
        return out + (["", missing] if missing else [])


def imo_table(covers: Sequence[DecayCover], amplitudes_deg: Sequence[float] = IMO_AMPLITUDES_DEG) -> ImoTable:
    """The IMO table of one condition's groups (``covers``, one hull, axis and draft)."""
    (condition,) = {cover.condition for cover in covers}
    covering = [c for c in covers if c.mean_amplitude_deg]
    if not covering:
        raise ValueError(f"{' '.join(map(str, condition))}: no decay passes a mean amplitude above the noise")
    low = min(min(c.mean_amplitude_deg) for c in covering)
    high = max(max(c.mean_amplitude_deg) for c in covering)
    largest = max(covering, key=lambda c: c.initial_deg)
    rows = [_row(covering, amplitude, largest) for amplitude in amplitudes_deg]
    angles = tuple(sorted(c.initial_deg for c in covers))
    points = tuple(
        (c.initial_deg, m, d)
        for c in covering
        for m, d in zip(c.mean_amplitude_deg, c.decrement_deg, strict=True)
    )
    return ImoTable(*condition, tuple(rows), (low, high), angles, points)


def _row(covers: Sequence[DecayCover], amplitude_deg: float, largest: DecayCover) -> ImoRow:
    """N at one amplitude from the groups that cover it (see the module's docstring)."""
    found = sorted((c for c in covers if c.covers(amplitude_deg)), key=lambda c: c.initial_deg)
    angles = tuple(c.initial_deg for c in found)
    if len(found) >= 2:
        values = np.array([c.bertin_n(amplitude_deg)[0] for c in found])
        spread = float(np.std(values, ddof=1) / math.sqrt(values.size))
        return ImoRow(amplitude_deg, float(values.mean()), spread, ANGLES_STD, angles)
    if found:
        value, std = found[0].bertin_n(amplitude_deg)
        return ImoRow(amplitude_deg, value, std, FIT_STD, angles)
    needed = None
    if amplitude_deg > max(largest.mean_amplitude_deg):
        needed = needed_initial_deg(largest, amplitude_deg)
    return ImoRow(amplitude_deg, math.nan, math.nan, None, (), needed)


def needed_initial_deg(cover: DecayCover, amplitude_deg: float) -> float:
    """The initial angle (deg) whose decay first passes the mean amplitude ``amplitude_deg``: φm plus half
    the decrement there, Δφ = N φm², N from ``cover``'s fit."""
    n_per_deg, _ = cover.bertin_n(amplitude_deg)
    return amplitude_deg + 0.5 * n_per_deg * amplitude_deg**2


def imo_tables(covers: Iterable[DecayCover]) -> list[ImoTable]:
    """One ``ImoTable`` per hull, axis and draft of the fitted groups, in that order; a condition none of
    whose decays passes an amplitude above the noise is left out."""
    by_condition: dict[tuple[str, str, float], list[DecayCover]] = defaultdict(list)
    for cover in covers:
        by_condition[cover.condition].append(cover)
    return [
        imo_table(found)
        for _, found in sorted(by_condition.items())
        if any(cover.mean_amplitude_deg for cover in found)
    ]


def imo_markdown(tables: Sequence[ImoTable]) -> str:
    """The campaign report's section: each condition's table ("" without any)."""
    if not tables:
        return ""
    body = "\n\n".join("\n".join(table.lines()) for table in tables)
    return f"\n## IMO table: Bertin's N against mean amplitude\n\n{body}\n"
