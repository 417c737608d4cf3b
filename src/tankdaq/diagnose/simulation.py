"""The simulation a lab compares its model test with: a time series from any code, a model, a prediction.

``Simulation`` is what the comparison reads, whatever the source: a name, a kind
(``series``: decays computed by some code, whose equation is identified here;
``model``: coefficients per unit inertia, such as a hull's ``[simulation]``;
``prediction``: coefficients a method predicts, such as simplified Ikeda), the
coefficients or the runs, and notes for the report. A source is one small
resolver (``RESOLVERS``: a name -> a function of the ``SimulationRequest``);
anything else given to ``--simulation`` is a file. Files are untrusted: their
runs are matched to the measured ones by initial angle, and a unit slip
(degrees read as radians, milliseconds as seconds) is refused in one line, as is a series that grows
(an unstable simulation is no decay) and a hull that is not the one the decays were recorded on.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from ..config.hulls import Hull, format_draft
from ..config.validation import input_file
from ..errors import InputError
from ..ident.conditions import UNKNOWN, condition_of
from ..ident.inputs import input_notices, read_decays
from ..ident.signals import half_cycle_peaks
from ..records import DecayRun
from .components import prediction_shares, table_shares
from .prediction_table import (
    component_changes,
    component_parts,
    coverage_note,
    equivalent_model,
    is_prediction_table,
    per_unit_inertia,
    read_prediction_table,
)


class SimulationKind(StrEnum):
    """What a simulation gives: simulated decays, a model's coefficients, or a damping prediction."""

    SERIES = "series"
    MODEL = "model"
    PREDICTION = "prediction"


SERIES, MODEL, PREDICTION = SimulationKind.SERIES, SimulationKind.MODEL, SimulationKind.PREDICTION
#: A simulated run matches a measured one when their initial angles differ by at most this fraction.
MATCH_TOLERANCE = 0.25
#: Ratios that mean a unit slip rather than another ship: degrees per radian, ms per s.
DEG_PER_RAD = math.degrees(1.0)
MS_PER_S = 1000.0
#: A free decay's swing only shrinks: a series whose half-cycle peaks grow this many times in a row, each
#: by more than ``GROWTH``, is an unstable simulation (energy fed in), not a set of decays.
GROWING_HALF_CYCLES, GROWTH = 4, 1.02


@dataclass(frozen=True)
class Simulation:
    """A simulation, typed: what the comparison needs whatever code or method made it."""

    name: str
    kind: SimulationKind
    coefficients: dict[str, float] = field(default_factory=dict)  # per unit inertia (model, prediction)
    runs: tuple[DecayRun, ...] = ()  # the simulated decays (series)
    notes: tuple[str, ...] = ()
    #: A prediction's own account of a measured b1, b2 (per unit inertia) at the amplitudes (rad): which of
    #: its components would have to change, and by how much (simplified Ikeda's ``required_change``).
    component_changes: Callable[[float, float, Sequence[float]], list[str]] | None = None
    #: A prediction's components: key -> the term of the model it is part of and its part (per unit
    #: inertia); what the correction is stated in (``diagnose.components``). None: the model's own terms.
    shares: dict[str, tuple[str, float]] | None = None
    #: The carriage speed the prediction is made at (m/s); None where the simulation does not say.
    speed_m_s: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in (SERIES, MODEL, PREDICTION):
            raise ValueError(f"simulation kind {self.kind!r}: use {SERIES}, {MODEL} or {PREDICTION}")


@dataclass(frozen=True)
class SeriesColumns:
    """How to read a simulation's CSV (the same settings as ``identify``'s CSV options)."""

    time_col: str = "time_s"
    angle_col: str = "angle_deg"
    rate_col: str | None = "rate_deg_s"
    angle_unit: str | None = None  # None: decided from the data, as for the measured files


@dataclass(frozen=True)
class SimulationRequest:
    """What a resolver may use: the measured runs (their amplitudes), the axis, the hull and draft."""

    measured: tuple[DecayRun, ...]
    axis: str = "roll"
    hull: Hull | None = None
    draft: float = 1.0
    columns: SeriesColumns = SeriesColumns()
    speed_m_s: float | None = None  # --speed: the carriage speed asked for the prediction

    def __post_init__(self) -> None:
        """A hull that is not the one the decays say they were recorded on (their metadata or file name,
        as ``identify`` reads it) is refused: its simulation, prediction or correction in SI would be
        another ship's."""
        if self.hull is None:
            return
        recorded = sorted({condition_of(run).hull for run in self.measured} - {UNKNOWN})
        if recorded and recorded != [self.hull.name]:
            raise InputError(
                f"the decays were recorded on hull {', '.join(recorded)}, not {self.hull.name} (--hull): "
                f"a simulation of {self.hull.name} says nothing of them; give --hull {recorded[0]}"
            )

    def speed(self) -> tuple[float, str]:
        """The carriage speed (m/s) a prediction is made at and where it comes from (``decay_speed``)."""
        hull_speed = None
        if self.hull is not None:
            hull_speed = self.hull.main_particulars.at(self.draft).get("speed_m_s")
        return decay_speed(self.measured, self.speed_m_s, hull_speed)

    def require_hull(self, source: str) -> Hull:
        if self.hull is None:
            raise InputError(f"--simulation {source} needs --hull NAME (and --draft) to take it from")
        return self.hull

    def amplitudes_rad(self) -> list[float]:
        """The measured runs' initial angles (rad, positive): where a prediction is evaluated."""
        return [abs(float(run.angle[0])) for run in self.measured]


Resolver = Callable[[SimulationRequest], Simulation]


def from_hull(request: SimulationRequest) -> Simulation:
    """The hull's ``[simulation]`` coefficients for the axis and draft, as given."""
    hull = request.require_hull("hull")
    model = hull.simulation_model(request.axis)
    coefficients = {k: v for k, v in model.coefficients(request.draft).items() if v != 0.0}
    name = f"hull {hull.name} {request.axis} at {format_draft(request.draft)}"
    notes = (f"source: {' '.join(model.source.split())}",) if model.source else ()
    return Simulation(name, MODEL, coefficients, notes=notes)


def recorded_speeds(runs: Sequence[DecayRun]) -> dict[float, list[str]]:
    """The carriage speeds the decays' metadata give (m/s, rounded to the mm/s) -> the runs at each."""
    speeds: dict[float, list[str]] = {}
    for run in runs:
        if run.meta.get("speed_m_s") is not None:
            speeds.setdefault(round(float(run.meta["speed_m_s"]), 3), []).append(run.name)
    return speeds


def decay_speed(runs: Sequence[DecayRun], asked: float | None, hull_speed: float | None) -> tuple[float, str]:
    """The speed a prediction of these decays is made at, and its source: the recordings' own speed (their
    metadata, as the catalogue holds it), else ``asked`` (--speed), else the hull's speed_m_s, else 0.
    Decays at two speeds, or --speed against the speed they were recorded at, are one line: a prediction
    at one speed says nothing of decays at another."""
    speeds = recorded_speeds(runs)
    if len(speeds) > 1:
        each = "; ".join(f"{v:g} m/s: {', '.join(names)}" for v, names in speeds.items())
        raise InputError(
            f"the decays were recorded at {len(speeds)} speeds ({each}): compare one speed at a time "
            "(its files, or --runs 'speed=...')"
        )
    if speeds:
        (recorded,) = speeds
        unlabelled = [run.name for run in runs if run.meta.get("speed_m_s") is None]
        if asked is not None and abs(asked - recorded) > 1e-3:
            raise InputError(
                f"--speed {asked:g} m/s, but the decays were recorded at {recorded:g} m/s: a prediction at "
                f"one speed says nothing of decays at another; drop --speed or give {recorded:g}"
            )
        if unlabelled:
            raise InputError(
                f"{', '.join(unlabelled)} give no speed, the other decays {recorded:g} m/s: compare the "
                "decays of one speed (or label them)"
            )
        if hull_speed is not None and abs(hull_speed - recorded) > 1e-3:
            return recorded, f"the recordings; not the hull's speed_m_s {hull_speed:g} m/s"
        return recorded, "the recordings"
    if asked is not None:
        if not (math.isfinite(asked) and asked >= 0):
            raise InputError(f"--speed {asked:g}: give the carriage speed in m/s, zero or more")
        return asked, "--speed"
    if hull_speed is not None:
        return hull_speed, "the hull's speed_m_s"
    return 0.0, "assumed: neither the recordings, --speed nor the hull give one"


def from_ikeda(request: SimulationRequest) -> Simulation:
    """The hull's simplified Ikeda prediction (``config.ikeda_prediction``) as a decay model.

    Its damping is predicted at the measured roll period (stiffness is not what Ikeda predicts) and
    made a linear + quadratic model over the measured amplitudes; every input outside the method's
    validity range is a note, and the prediction explains a measured damping in its components.
    """
    from ..config.hulls import ikeda_prediction
    from ..physics.ikeda import LIMITS

    hull = request.require_hull("ikeda")
    if request.axis != "roll":
        raise InputError(f"--simulation ikeda predicts roll damping; these decays are {request.axis}")
    period_s = dominant_period_s(request.measured)
    speed, speed_from = request.speed()
    prediction = ikeda_prediction(hull, request.draft, speed, period_s=period_s)
    model = prediction.equivalent_model(request.amplitudes_rad())
    shares = prediction_shares(prediction, request.amplitudes_rad())
    notes = (
        f"simplified Ikeda (Kawahara, Maekawa and Ikeda 2009) at the measured period {period_s:.4g} s "
        f"and speed {speed:g} m/s ({speed_from})",
        *(
            f"outside the method's range: {finding.line}" if finding.name in LIMITS else finding.line
            for finding in prediction.findings
        ),
    )
    name = f"ikeda {hull.name} at {format_draft(request.draft)}"
    return Simulation(
        name, PREDICTION, model, notes=notes, component_changes=prediction.required_change, shares=shares,
        speed_m_s=speed,
    )  # fmt: skip


#: Named sources; anything else is a file. A prediction method joins with one resolver here.
RESOLVERS: dict[str, Resolver] = {"hull": from_hull, "ikeda": from_ikeda}


def resolve_simulation(sources: Sequence[str], request: SimulationRequest) -> Simulation:
    """The simulation ``--simulation`` names: a resolver by name, or one or more files (CSV, MCAP)."""
    if not sources:
        raise InputError("--simulation needs a source: a decay file, a damping table, hull, or ikeda")
    named = [s for s in sources if s in RESOLVERS]
    if named and len(sources) > 1:
        raise InputError(f"--simulation {named[0]} stands alone; files are given one --simulation each")
    if named:
        return RESOLVERS[named[0]](request)
    paths = [Path(s) for s in sources]
    tables = [path for path in paths if is_prediction_table(path)]
    if tables and len(paths) > 1:
        raise InputError(f"--simulation {tables[0]} (a prediction table) stands alone; give one table")
    return from_table(tables[0], request) if tables else from_series(paths, request)


def from_table(path: Path, request: SimulationRequest) -> Simulation:
    """A damping prediction made elsewhere, a table of damping against amplitude
    (``diagnose.prediction_table``), as a decay model at the measured period."""
    if request.axis != "roll":
        raise InputError(
            f"--simulation {path.name}: a damping table is a roll prediction; these are {request.axis}"
        )
    period_s = dominant_period_s(request.measured)
    omega = 2.0 * math.pi / period_s
    table = read_prediction_table(path)
    b_eq, how = per_unit_inertia(
        table.damping, table.column, request.hull, request.draft, request.axis, omega**2, path.name
    )
    model = equivalent_model(table.amplitudes_rad, b_eq, omega)
    parts = f", components {', '.join(table.components)}" if table.components else ""
    notes = [
        f"a damping prediction ({table.column}{parts}, {table.amplitudes_rad.size} amplitude(s)) at the "
        f"measured period {period_s:.4g} s",
        *([how] if how else []),
        *table.notes,
    ]
    if (outside := coverage_note(table.amplitudes_rad, request.amplitudes_rad())) is not None:
        notes.append(outside)
    explain = component_changes(table, b_eq, omega)
    shares = table_shares(omega, *component_parts(table, b_eq)) if table.components else None
    return Simulation(
        path.name, PREDICTION, model, notes=tuple(notes), component_changes=explain, shares=shares
    )


def from_series(paths: Sequence[Path], request: SimulationRequest) -> Simulation:
    """Simulated decays from files, read like measured ones (release found, columns and unit as asked)."""
    cols = request.columns
    runs: list[DecayRun] = []
    for path in paths:
        input_file(path)
        try:
            found = read_decays(
                path, request.axis, cols.time_col, cols.angle_col, cols.rate_col, cols.angle_unit
            )
        except InputError as exc:  # the reading's own words name the measured files' options
            said = re.sub(r"--(time-col|angle-col|rate-col|angle-unit)\b", r"--sim-\1", str(exc))
            raise type(exc)(f"simulation {path.name}: {said}") from None
        _refuse_growing(path, read_decays(path, request.axis, cols.time_col, cols.angle_col, cols.rate_col,
                                          cols.angle_unit, keep_all=True))  # fmt: skip
        runs += [_renamed(run, f"sim:{run.name}") for run in found]
    rates = sorted({round(run.sample_rate, 3) for run in runs})
    notes = (f"simulated at {', '.join(f'{r:g}' for r in rates)} Hz", *input_notices(runs))
    name = ", ".join(p.name for p in paths)
    simulated, measured = set(recorded_speeds(runs)), set(recorded_speeds(request.measured))
    if simulated and measured and simulated != measured:
        raise InputError(
            f"simulation {name} is at {', '.join(f'{v:g}' for v in sorted(simulated))} m/s, the decays were "
            f"recorded at {', '.join(f'{v:g}' for v in sorted(measured))} m/s: simulate at the decays' speed"
        )
    speed = simulated.pop() if len(simulated) == 1 else None
    return Simulation(name, SERIES, runs=tuple(runs), notes=notes, speed_m_s=speed)


def _refuse_growing(path: Path, records: Sequence[DecayRun]) -> None:
    """One line when a simulated record's swing grows (``GROWING_HALF_CYCLES`` peaks in a row): read as
    decays it would be cut into 'decays' at each larger swing."""
    for record in records:
        y = record.angle - float(np.median(record.angle))
        peaks = np.abs(y[half_cycle_peaks(y)])
        grows = np.concatenate([[False], peaks[1:] > GROWTH * peaks[:-1], [False]])
        edges = np.flatnonzero(np.diff(grows.astype(int)))  # each streak: the peak before it, its last
        for start, end in zip(edges[::2], edges[1::2], strict=True):
            if end - start >= GROWING_HALF_CYCLES:
                raise InputError(
                    f"simulation {path.name} grows: its swing rises from {math.degrees(peaks[start]):.3g} "
                    f"to {math.degrees(peaks[end]):.3g} deg over {end - start} half-cycles (unstable: "
                    "energy fed in, a negative damping or a time step too long); a decay's swing only shrinks"
                )


def _renamed(run: DecayRun, name: str) -> DecayRun:
    return DecayRun(run.t, run.angle, run.rate, run.axis, name, run.channels, run.meta)


@dataclass(frozen=True)
class Match:
    """A measured run and the simulated run released nearest its initial angle."""

    measured: str
    simulated: str
    measured_angle_rad: float
    simulated_angle_rad: float

    @property
    def line(self) -> str:
        return (
            f"{self.measured} ({math.degrees(self.measured_angle_rad):+.2f} deg) <-> {self.simulated} "
            f"({math.degrees(self.simulated_angle_rad):+.2f} deg)"
        )


def match_runs(measured: Sequence[DecayRun], simulated: Sequence[DecayRun]) -> list[Match]:
    """Each measured run with the simulated run of nearest initial |angle|, within ``MATCH_TOLERANCE``.

    A unit slip shows as a ratio of 57 (degrees read as radians) and is refused
    with what to do; nothing matching at all is refused with both sets of angles.
    """
    sim_angles = np.array([abs(float(r.angle[0])) for r in simulated])
    matches = []
    for run in measured:
        angle = abs(float(run.angle[0]))
        i = int(np.argmin(np.abs(sim_angles - angle)))
        if abs(sim_angles[i] - angle) <= MATCH_TOLERANCE * angle:
            matches.append(
                Match(run.name, simulated[i].name, float(run.angle[0]), float(simulated[i].angle[0]))
            )
    if matches:
        return matches
    measured_angles = np.array([abs(float(r.angle[0])) for r in measured])
    for factor, unit in ((DEG_PER_RAD, "deg"), (1.0 / DEG_PER_RAD, "rad")):
        slip = np.abs(sim_angles[:, None] / factor - measured_angles) <= MATCH_TOLERANCE * measured_angles
        if np.any(slip):
            raise InputError(
                f"the simulation's angles are about {factor:.3g} times the measured: a unit slip; "
                f"read the simulation with --sim-angle-unit {unit}"
            )
    degrees = ", ".join(f"{math.degrees(a):.1f}" for a in sim_angles)
    wanted = ", ".join(f"{math.degrees(abs(r.angle[0])):.1f}" for r in measured)
    raise InputError(
        f"no simulated run starts near a measured one (simulated from {degrees} deg, measured from "
        f"{wanted} deg, within {100 * MATCH_TOLERANCE:.0f} %): simulate from the measured release angles"
    )


def check_time_scale(measured: Sequence[DecayRun], simulated: Sequence[DecayRun]) -> None:
    """Refuse a simulation whose period is not within a factor 2 of the measured (a time-unit slip)."""
    ratio = dominant_period_s(simulated) / dominant_period_s(measured)
    if 0.5 <= ratio <= 2.0:
        return
    hint = ""
    if abs(ratio / MS_PER_S - 1.0) < 0.3:
        hint = ": its time column is in ms, write seconds"
    elif abs(ratio * MS_PER_S - 1.0) < 0.3:
        hint = ": the measured time column is in ms, write seconds"
    raise InputError(
        f"the simulation's period is {ratio:.3g} times the measured ({dominant_period_s(simulated):.4g} s "
        f"against {dominant_period_s(measured):.4g} s){hint or ': is it the same ship and time unit?'}"
    )


def dominant_period_s(runs: Sequence[DecayRun]) -> float:
    """The median over runs of the period of the angle's spectral peak (zero-padded FFT)."""
    periods = []
    for run in runs:
        x = run.angle - np.mean(run.angle)
        n_fft = 8 * x.size
        power = np.abs(np.fft.rfft(x, n_fft))
        freqs = np.fft.rfftfreq(n_fft, 1.0 / run.sample_rate)
        periods.append(1.0 / freqs[int(np.argmax(power[1:])) + 1])
    return float(np.median(periods))
