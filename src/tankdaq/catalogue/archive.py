"""``tankdaq import FOLDER --out recordings/`` (``tankdaq.import_archive``): a lab's archive converted into
recordings (``api.archive``) and catalogued (``catalogue.index``), idempotently: a decay imported before
is found where it was written (its source's SHA-256 and place in the file name it), and its row by its
own SHA-256, so importing again writes and adds nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..api import arguments
from ..api.archive import ArchiveImport, import_folder
from ..api.progress import Progress
from .database import describe, open_catalogue, resolve_url
from .index import IndexReport, index_files


@dataclass
class ArchiveReport:
    """An import (``api.archive.ArchiveImport``) and what the catalogue made of its recordings (None: the
    catalogue is switched off, ``--catalogue none``)."""

    imported: ArchiveImport
    catalogued: IndexReport | None
    catalogue: str | None  # where, as people see it (a password never shown)

    @property
    def line(self) -> str:
        where = f"; catalogue {self.catalogue}: {self.catalogued.line}" if self.catalogued else ""
        return f"{self.imported.line}{where}"


def import_archive(
    folder: str | Path,
    out: str | Path,
    *,
    catalogue: str | None = None,
    axis: str | None = None,
    time_col: str = "time_s",
    angle_col: str = "angle_deg",
    speed_col: str | None = None,
    progress: Progress | None = None,
) -> ArchiveReport:
    """Every decay of every file under ``folder`` as a recording in ``out``, each with its provenance, and
    catalogued (``catalogue``: a URL or path, None: ``$TANKDAQ_CATALOGUE`` or the user's, "none": off)."""
    given = arguments.optional_text(catalogue, "catalogue", "a catalogue URL or path, 'none', or None")
    url = resolve_url(given)  # a catalogue not understood: one line before any file is read
    imported = import_folder(
        folder, out, axis=axis, time_col=time_col, angle_col=angle_col, speed_col=speed_col, progress=progress
    )
    if url is None:
        return ArchiveReport(imported, None, None)
    with open_catalogue(url) as opened:
        report = index_files(opened, [decay.path for decay in imported.decays])
    return ArchiveReport(imported, report, describe(url))
