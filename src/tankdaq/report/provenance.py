"""Where a report's numbers come from, as a reviewer asks: the hull files and their SHA-256, each
recording's hash, device id, product code and firmware (from its own metadata), the software that wrote
it and made the report, the catalogue ids, and the command line (a catalogue password masked)."""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .content import ReportTable, Section

if TYPE_CHECKING:
    from ..api.recording import Recording
    from ..config.hulls import Hull

#: What the Python API writes where the command line would be.
API_CALL = "tankdaq.make_report (Python API)"


def masked_command(argv: Sequence[str]) -> str:
    """A command line as the report prints it: every URL without its password (``--catalogue
    postgresql://user:secret@host/db`` and ``--catalogue=...`` alike). The catalogue's module (and
    SQLAlchemy, a third of a second) is imported only for a command line that holds a URL."""

    def masked(word: str) -> str:
        if "://" not in word:
            return word
        from ..catalogue.location import describe

        option, equals, value = word.partition("=")
        if equals and option.startswith("-"):
            return f"{option}={describe(value)}"
        return describe(word)

    return shlex.join([masked(word) for word in argv])


def provenance_section(
    recordings: Sequence[Recording],
    hulls: Sequence[Hull],
    catalogue_ids: Mapping[Path, int],
    sessions: Sequence[Path],
    command: str,
) -> Section:
    """The provenance: the report's own line (software, command, sessions), the hull files and the
    recordings."""
    import tankdaq

    from ..store.inputs import file_sha256

    about = [
        ["software", f"tankdaq {tankdaq.__version__}"],
        ["command", command],
        *[["session folder", str(folder)] for folder in sessions],
    ]
    hull_rows = [
        [hull.name, str(hull.path) if hull.path else None, file_sha256(hull.path) if hull.path else None]
        for hull in hulls
    ]
    recording_rows = []
    for recording in recordings:
        stored = recording.meta.get("stored", {})
        recording_rows.append([
            str(recording.path), file_sha256(recording.path), stored.get("device_id"),
            stored.get("product_code"), stored.get("firmware"), stored.get("software_version"),
            catalogue_ids.get(recording.path.resolve()),
        ])  # fmt: skip
    hull_caption = "The hull files the dimensional results read." if hulls else "No hull file was read."
    return Section(
        "provenance",
        "Provenance",
        [
            ReportTable("report", "Report", ["item", "value"], about),
            ReportTable("hulls", "Hull files", ["hull", "file", "SHA-256"], hull_rows, hull_caption),
            ReportTable(
                "recordings",
                "Recordings",
                [
                    "file",
                    "SHA-256",
                    "device id",
                    "product code",
                    "firmware",
                    "written by tankdaq",
                    "catalogue id",
                ],
                recording_rows,
                "Device id, product code and firmware as each recording's metadata holds them (– where "
                "the file does not say: a CSV, a simulated device).",
            ),
        ],
    )
