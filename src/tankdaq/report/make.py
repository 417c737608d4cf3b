"""``tankdaq.make_report``: the report of recordings, a guided session or a catalogue query, written as
one self-contained HTML file and a PDF; ``tankdaq report`` is this call.

Every argument and output name is checked before any file is read; the recordings are read once (their
metadata is the provenance), grouped by condition and fitted by ``tankdaq.identify`` with the
condition's hull and draft; the content is built, then rendered. A rerun on the same inputs gives the
same numbers: only ``made_utc`` differs (give it to make the files the same too).
"""

from __future__ import annotations

import datetime
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..api import arguments
from ..api.progress import Kept, Progress
from ..config import validation
from ..errors import InputError
from .content import ReportContent

if TYPE_CHECKING:
    from ..api.identification import ConditionFit, Reading
    from ..api.recording import Recording
    from ..config.hulls import Hull, WaterSettings
    from ..ident.conditions import Condition
    from .sources import ReportInputs

#: The names written into ``out``.
HTML_NAME, PDF_NAME = "report.html", "report.pdf"


@dataclass(frozen=True, eq=False)  # holds figures: compared by identity
class Report:
    """What ``make_report`` made: its ``content`` (tables, figures, warnings, provenance), the ``files``
    written (HTML, PDF) and the lines the reading and fitting had (``notices``).

    >>> report = tankdaq.make_report("recordings/", out="report")  # doctest: +SKIP
    >>> report.tables["c1-coefficients"]  # a DataFrame  # doctest: +SKIP
    """

    content: ReportContent
    files: list[Path]
    notices: list[str]

    @property
    def document(self) -> dict[str, Any]:
        """What ``tankdaq report --json`` prints: the numbers the HTML and the PDF hold."""
        return self.content.document()

    @property
    def warnings(self) -> list[str]:
        return list(self.content.warnings)

    @property
    def tables(self) -> dict[str, Any]:
        """Every table by its key, as a DataFrame."""
        return {table.key: table.to_frame() for table in self.content.tables}

    def to_json(self) -> str:
        from ..api.identification import to_json

        return to_json(self.document)


def make_report(
    inputs: str | Path | Sequence[str | Path] | None = None,
    *,
    runs: str | None = None,
    catalogue: str | Path | None = None,
    out: str | Path | None = None,
    html: str | Path | None = None,
    pdf: str | Path | None = None,
    model: str = "auto",
    hull: str | Path | None = None,
    full_scale: bool = False,
    water_temperature_c: float | None = None,
    sea_temperature_c: float | None = None,
    reading: Reading | None = None,
    command: str | None = None,
    made_utc: datetime.datetime | None = None,
    progress: Progress | None = None,
) -> Report:
    """The report of ``inputs`` (recordings, folders of them, glob patterns, guided session folders:
    their accepted decays) or of the catalogue's ``runs`` query (``"hull=swath draft=T"``, in
    ``catalogue``), written to ``out`` (a folder: report.html and report.pdf) and/or the names ``html``
    and ``pdf``; none: nothing written (``Report.document`` still holds the numbers). Each condition is
    fitted with ``model``; ``hull`` (a name or .toml) for every condition, else each condition's own
    hull by the name its recordings give; ``full_scale`` adds the ship's (the hull's scale factor) by
    Froude and friction-corrected at ``water_temperature_c``/``sea_temperature_c`` (as ``identify``);
    ``reading`` says how decay files (CSV, HDF5, ...) are read (its column settings).
    ``command`` is the command line the provenance names; ``made_utc`` the time it says (default now).
    Bad input raises ``tankdaq.errors.InputError`` before any file is read; an existing output name is
    refused.

    >>> tankdaq.make_report("sessions/try", out="sessions/try/handover")  # doctest: +SKIP
    """
    from ..api.identification import Reading, water_settings
    from ..config.hulls import full_scale_of, load_hull
    from ..physics.models import resolve_model
    from .provenance import API_CALL
    from .sources import report_inputs

    paths = (
        [] if inputs is None else arguments.paths(inputs, "inputs", "a path, a pattern, or a list of them")
    )
    runs = arguments.optional_text(runs, "runs", 'a query as "hull=swath draft=T", or None')
    url = (
        None if catalogue is None else str(arguments.path(catalogue, "catalogue", "a catalogue URL or path"))
    )
    html_path, pdf_path = output_paths(out, html, pdf)
    model = arguments.model(model)
    hull = arguments.optional_path(hull, "hull", "a hull's name, a .toml path, or None")
    full_scale = arguments.flag(full_scale, "full_scale")
    water = water_settings(water_temperature_c, sea_temperature_c)
    if reading is not None and not isinstance(reading, Reading):
        raise arguments.refuse("reading", "a tankdaq.Reading or None", reading)
    command = arguments.optional_text(command, "command", "the command line as text, or None") or API_CALL
    made = _made(made_utc)
    kept = Kept(arguments.progress(progress))
    resolve_model(model)  # a typo fails before any file is read
    given_hull = load_hull(str(hull)) if hull is not None else None
    if given_hull is not None:
        full_scale_of(given_hull, full_scale)
    found = report_inputs(paths, runs, url)
    for line in found.lines:
        kept.line(line)
    recordings, skipped = _read(found.files, reading or Reading(), kept)
    groups = _by_condition(recordings)
    hulls = {condition: given_hull or _hull_named(condition, kept) for condition in groups}
    read_hulls = list({id(h): h for h in hulls.values() if h is not None}.values())
    for condition_hull in read_hulls:
        full_scale_of(condition_hull, full_scale)  # every condition's hull has its scale: before any fit
    fits = [
        _fit(group, condition, hulls[condition], model, full_scale, water, kept)
        for condition, group in groups.items()
    ]
    content = _content(fits, skipped, recordings, read_hulls, found, command, made)
    return Report(content, write_report(content, html_path, pdf_path), kept.lines)


def output_paths(out: object, html: object, pdf: object) -> tuple[Path | None, Path | None]:
    """Where the HTML and the PDF go (``out``'s names, or the names given), each checked writable and
    free (never over a file) before any work."""
    folder = arguments.optional_path(out, "out", "a folder (str or pathlib.Path) or None")
    html_path = arguments.optional_path(html, "html", "an .html file's path or None")
    pdf_path = arguments.optional_path(pdf, "pdf", "a .pdf file's path or None")
    if folder is not None:
        validation.output_dir(folder, "--out")
        html_path, pdf_path = html_path or folder / HTML_NAME, pdf_path or folder / PDF_NAME
    for path, option, suffixes in ((html_path, "--html", (".html", ".htm")), (pdf_path, "--pdf", (".pdf",))):
        if path is None:
            continue
        if path.suffix.lower() not in suffixes:
            raise InputError(f"{option} {path}: give a name ending in {' or '.join(suffixes)}")
        if folder is None or path.parent != folder:
            validation.output_file(path, option)
        validation.refuse_existing([path])
    return html_path, pdf_path


def _made(value: object) -> str:
    """The time the report says it was made: given (an aware datetime, in UTC), or now."""
    if value is None:
        return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    if isinstance(value, datetime.datetime) and value.tzinfo is not None:
        return value.astimezone(datetime.UTC).isoformat(timespec="seconds")
    raise arguments.refuse("made_utc", "a datetime with its time zone, or None", value)


def _read(files: list[Path], reading: Reading, kept: Kept) -> tuple[list[Recording], list[str]]:
    """Every file read once (a copy or an export of another left out, said); one without a decay is
    left out with a warning; none with a decay is refused."""
    from ..api.identification import drop_read_twice
    from ..api.recording import read

    recordings, skipped = [], []
    for path in drop_read_twice(files, kept):
        recording = read(
            path, axis=reading.axis, time_col=reading.time_col, angle_col=reading.angle_col,
            rate_col=reading.rate_col, angle_unit=reading.angle_unit, time_unit=reading.time_unit,
        )  # fmt: skip
        if recording.decays:
            recordings.append(recording)
        else:
            skipped.append(f"{path}: no decay (no release recorded): not in this report")
    if not recordings:
        raise InputError(skipped[0] if len(skipped) == 1 else "no decay in any file given")
    return recordings, skipped


def _by_condition(recordings: list[Recording]) -> dict[Condition, list[Recording]]:
    """The recordings by the condition their first decay says (a recording is one condition)."""
    from ..ident.conditions import condition_of

    groups: dict[Condition, list[Recording]] = {}
    for recording in recordings:
        groups.setdefault(condition_of(recording.decays[0].run), []).append(recording)
    return groups


def _hull_named(condition: Condition, kept: Kept) -> Hull | None:
    """The hull a condition's recordings name, when it can be found (else a line: no dimensional
    results for it)."""
    from ..config.hulls import load_hull
    from ..ident.conditions import UNKNOWN

    if condition.hull == UNKNOWN:
        return None
    try:
        return load_hull(condition.hull)
    except InputError:
        kept.line(
            f"{condition.label}: hull {condition.hull!r} not found; no dimensional results (give --hull)"
        )
        return None


def _fit(
    group: list[Recording], condition: Condition, hull: Hull | None, model: str, full_scale: bool,
    water: WaterSettings, kept: Kept,
) -> ConditionFit:  # fmt: skip
    """One condition fitted by ``tankdaq.identify`` at its draft (T where the recordings do not say)."""
    from ..api.identification import identify
    from ..config.hulls import parse_draft
    from ..ident.conditions import UNKNOWN

    draft = 1.0 if condition.draft == UNKNOWN else parse_draft(condition.draft)
    if condition.draft == UNKNOWN and hull is not None:
        kept.line(f"{condition.label}: the recordings give no draft; dimensional results at T")
    hull_file = None if hull is None else hull.path or hull.name
    found = identify(
        group, model, hull=hull_file, draft=draft, full_scale=full_scale, progress=kept,
        water_temperature_c=water.water_temperature_c, sea_temperature_c=water.sea_temperature_c,
    )  # fmt: skip
    (fit,) = found.fits
    return fit


def _content(
    fits: list[ConditionFit], skipped: list[str], recordings: list[Recording], hulls: list[Hull],
    found: ReportInputs, command: str, made: str,
) -> ReportContent:  # fmt: skip
    from .build import report_content
    from .provenance import provenance_section

    warnings = skipped + [f"{fit.label}: {line}" for fit in fits for line in fit.summary.warnings]
    provenance = provenance_section(recordings, hulls, found.catalogue_ids, found.sessions, command)
    return report_content(fits, warnings, provenance, made)


def write_report(content: ReportContent, html_path: Path | None, pdf_path: Path | None) -> list[Path]:
    """The HTML and the PDF, each a new file (``store.safe_write``), the folder made where needed."""
    from ..store.safe_write import write_text_new
    from .html import render_html

    written = []
    if html_path is not None:
        html_path.parent.mkdir(parents=True, exist_ok=True)
        written.append(write_text_new(html_path, render_html(content)))
    if pdf_path is not None:
        from .pdf import write_pdf

        pdf_path.parent.mkdir(parents=True, exist_ok=True)
        written.append(write_pdf(content, pdf_path))
    return written
