"""``tankdaq.diagnose``: what a decay model is missing, or what a lab's simulation misses; ``tankdaq
diagnose`` (with or without ``--simulation``) is this call.

Without a simulation the decays' own baseline is fitted and the effects its residuals show are added
(``diagnose.workflow.Diagnoser``); with one (a time series, a hull's ``[simulation]`` model or an Ikeda
prediction, ``diagnose.simulation``) the simulation is the baseline, compared with the decays and corrected
(``diagnose.compare.SimulationComparison``). Either way the result is told the same four ways, by
``diagnose.report`` or ``diagnose.sim_report``: the story, the JSON, the Markdown report and the .rrd.
"""

from __future__ import annotations

import html
import itertools
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from ..config import validation
from ..errors import InputError
from ..records import DecayRun
from . import arguments
from .identification import Reading, Source, load_runs, truncations
from .progress import Kept, Progress
from .recording import sources_given

if TYPE_CHECKING:
    from ..diagnose.compare import SimulationComparison
    from ..diagnose.workflow import Diagnoser

#: The baseline ``diagnose`` fits when none is given: linear damping and stiffness.
DEFAULT_BASELINE = "b1,c1"


@dataclass(frozen=True, eq=False)  # holds fits: compared by identity
class Diagnosis:
    """What ``diagnose`` found: ``story`` (the lines ``tankdaq diagnose`` prints), ``document`` (its
    ``--json``, less the truncation keys: ``truncated_files`` lists the recordings cut short), the fitted
    ``diagnoser`` (``diagnose.workflow.Diagnoser``) or, with a simulation, ``comparison``
    (``diagnose.compare.SimulationComparison``), ``runs`` (the decays it fitted) and ``estimator`` (their
    final fit: the diagnosis's final model, or the measurement's own model a simulation is compared
    with), ``report`` (the Markdown report written, when asked).

    >>> found = tankdaq.diagnose("run.mcap", simulation="ikeda", hull="kvlcc2")  # doctest: +SKIP
    >>> print("\\n".join(found.story))  # doctest: +SKIP
    """

    diagnoser: Diagnoser | None
    comparison: SimulationComparison | None
    runs: list[DecayRun]
    estimator: Any
    story: list[str]
    document: dict[str, Any]
    notices: list[str]
    report: Path | None
    truncated_files: list[str]

    def save_rrd(self, path: str | Path) -> Path:
        """The story as a rerun recording (.rrd) for the viewer."""
        path = validation.output_file(arguments.path(path, "path", "a file path for the .rrd"), "path")
        fitted = self.comparison if self.comparison is not None else self.diagnoser
        return Path(_teller(self.comparison is not None).save_rrd(fitted, path))

    def _repr_html_(self) -> str:
        return f"<pre>{html.escape(chr(10).join(self.story))}</pre>"


def diagnose(
    sources: Source | Sequence[Source],
    *,
    baseline: str | None = None,
    max_steps: int = 4,
    reading: Reading | None = None,
    simulation: str | Path | Sequence[str | Path] | None = None,
    simulation_reading: Reading | None = None,
    hull: str | Path | None = None,
    draft: float | str = 1.0,
    speed: float | None = None,
    report: str | Path | None = None,
    progress: Progress | None = None,
) -> Diagnosis:
    """Find what a decay model is missing: fit ``baseline`` (default ``"b1,c1"``), read the residuals,
    add the effects they show (at most ``max_steps``) and tell the gap shrink. With ``simulation`` (CSV
    or MCAP files, ``"hull"`` for ``hull``'s ``[simulation]`` model at ``draft``, or ``"ikeda"`` for its
    simplified Ikeda prediction) the simulation is the baseline: compared with the decays, what it misses
    named and added, the correction given in SI with ``hull``. ``simulation_reading`` reads the
    simulation's files (default: as ``reading`` reads the decays); ``speed`` the carriage speed (m/s) a
    prediction is made at (default: the recordings' own, else the hull's ``speed_m_s``, else 0; decays
    recorded at another speed, or at two, are refused in one line); ``report`` a folder for the Markdown
    report. Bad input raises ``tankdaq.errors.InputError`` before any fit.

    >>> tankdaq.diagnose("run.mcap").story  # doctest: +SKIP
    >>> tankdaq.diagnose("run.mcap", simulation="hull", hull="swath").document["verdict"]  # doctest: +SKIP
    """
    sources = sources_given(sources)
    baseline = None if baseline is None else arguments.model(baseline, "baseline")
    max_steps = arguments.whole(max_steps, "max_steps", 0, 1000)
    reading = arguments.optional_instance(reading, "reading", Reading, "a tankdaq.Reading or None")
    if simulation is not None:  # "hull", "ikeda", or files
        named = isinstance(simulation, str) and simulation in ("hull", "ikeda")
        takes = "a path, a list of paths, 'hull' or 'ikeda'"
        files: list[str | Path] = (
            [str(simulation)] if named else [*arguments.paths(simulation, "simulation", takes)]
        )
        simulation = files
    simulation_reading = arguments.optional_instance(
        simulation_reading, "simulation_reading", Reading, "a tankdaq.Reading or None"
    )
    hull = arguments.optional_path(hull, "hull", "a hull's name, a .toml path, or None")
    draft = arguments.draft(draft)
    report = arguments.optional_path(report, "report", "a folder (str or pathlib.Path) or None")
    progress = arguments.progress(progress)
    if speed is not None:
        speed = arguments.number(speed, "speed", 0.0, unit="m/s")
        if simulation is None:
            raise InputError("speed applies with a simulation (the speed a prediction is made at)")
    if simulation is not None and baseline is not None:
        raise InputError("baseline does not apply with a simulation: the simulation is the baseline")
    if hull is not None and simulation is None:
        raise InputError("hull applies with a simulation (the hull's model, and the correction in SI)")
    names = _teller(simulation is not None).REPORT_FILES  # a report never writes over a file
    folder = validation.report_dir(Path(report), names, "report") if report is not None else None
    kept = Kept(progress)
    reading = reading or Reading(axis="roll")
    runs = load_runs(sources, reading, kept)
    cut = truncations(runs)
    for line in cut.values():
        kept.line(line)
    if simulation is None:
        diagnoser = _diagnose(runs, baseline or DEFAULT_BASELINE, max_steps, kept)
        fitted: Any = diagnoser
        estimator, comparison = diagnoser.final_.estimator, None
    else:
        given = [simulation] if isinstance(simulation, str | Path) else list(simulation)
        setting = (simulation_reading or reading, hull, draft, speed, max_steps)
        comparison = _compare(runs, given, *setting, kept)
        fitted, runs, estimator, diagnoser = comparison, comparison.runs_, comparison.reference_, None
    teller = _teller(comparison is not None)
    written = teller.write_report(fitted, folder) if folder is not None else None
    document = json.loads(teller.summary_json(fitted))
    story = teller.story(fitted)
    return Diagnosis(diagnoser, comparison, runs, estimator, story, document, kept.lines, written, list(cut))


def _teller(simulated: bool) -> ModuleType:
    """The module that words a result (``story``, ``summary_json``, ``write_report``, ``save_rrd``)."""
    from ..diagnose import report, sim_report

    return sim_report if simulated else report


def _diagnose(runs: list[DecayRun], baseline: str, max_steps: int, kept: Kept) -> Diagnoser:
    from ..diagnose.effects import LIBRARY
    from ..diagnose.workflow import Diagnoser
    from ..live.preparation import prepare_identifier

    prepare_identifier(baseline, kept.line)  # the native kernels: built once, on the first run
    with kept.task("baseline", 1 + max_steps * (len(LIBRARY) + 2)) as advance:
        count = itertools.count(1)
        step = lambda label: advance(next(count), description=f"fit: {label}")  # noqa: E731
        return Diagnoser(baseline=baseline, max_steps=max_steps, progress=step).fit(runs)


def _compare(
    runs: list[DecayRun],
    simulation: list[str | Path],
    simulation_reading: Reading,
    hull_name: str | Path | None,
    draft: float | str,
    speed: float | None,
    max_steps: int,
    kept: Kept,
) -> SimulationComparison:
    """The simulation resolved and checked against the decays' axis and the hull's drafts, compared."""
    from ..config.hulls import format_draft, load_hull
    from ..diagnose.compare import CANDIDATES, SimulationComparison
    from ..diagnose.simulation import SeriesColumns, SimulationRequest, resolve_simulation
    from ..live.preparation import prepare_identifier

    factor = validation.draft_factor(draft if isinstance(draft, str) else format_draft(float(draft)))
    hull = load_hull(str(hull_name)) if hull_name is not None else None
    axis = runs[0].axis
    if hull is not None:
        validation.hull_draft(hull, factor, axis)
    r = simulation_reading
    columns = SeriesColumns(r.time_col, r.angle_col, r.rate_col, r.angle_unit)
    request = SimulationRequest(tuple(runs), axis, hull, factor, columns, speed)
    sim = resolve_simulation([str(source) for source in simulation], request)
    prepare_identifier("b1,b2,c1,c3", kept.line)  # the native kernels: built once, on the first run
    with kept.task("comparing", 4 + max_steps * len(CANDIDATES)) as advance:
        count = itertools.count(1)
        step = lambda label: advance(next(count), description=f"fit: {label}")  # noqa: E731
        return SimulationComparison(sim, max_steps=max_steps, hull=hull, progress=step).fit(runs)
