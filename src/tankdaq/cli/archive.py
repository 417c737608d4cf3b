"""``tankdaq import FOLDER --out recordings/``: a lab's archive converted into catalogued recordings."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ..config import validation
from .app import app, catalogue_option, checked, handles_errors, say
from .options import AngleColumn, ReadAxis, SpeedColumn, TimeColumn

if TYPE_CHECKING:
    from ..api.archive import ArchiveImport


@app.command("import")
@handles_errors
def import_command(
    folder: Annotated[
        Path,
        typer.Argument(exists=True, file_okay=False, dir_okay=True, help="The lab's files (searched deep)."),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            callback=checked(validation.output_dir),
            help="Folder for the recordings (one .mcap per decay; a file tankdaq did not write is never "
            "replaced).",
        ),
    ],
    axis: ReadAxis = None,
    time_col: TimeColumn = "time_s",
    angle_col: AngleColumn = "angle_deg",
    speed_col: SpeedColumn = None,
    catalogue: Annotated[str | None, catalogue_option()] = None,
) -> None:
    """Every decay found in every file under FOLDER (recordings, CSV, HDF5, MATLAB, Parquet, LabVIEW TDMS,
    MT Manager logs and exports; several per file) as a recording in --out with its provenance (the source
    file, its SHA-256, its header, the conversions made), catalogued. Files that are no decays are listed
    with why. Importing again adds nothing."""
    from ..catalogue.archive import import_archive
    from .app import TerminalProgress

    found = import_archive(
        folder, out, catalogue=catalogue, axis=axis, time_col=time_col, angle_col=angle_col,
        speed_col=speed_col, progress=TerminalProgress(),
    )  # fmt: skip
    _table(found.imported)
    for path, why in found.imported.not_decays.items():
        say(f"not a decay: {path}: {why}")
    for line in found.imported.not_written:
        say(f"error: {line}")
    typer.echo(found.line)


def _table(found: ArchiveImport) -> None:
    """The decays, one row each: the source, which decay, where it is now, new or imported before."""
    from rich.console import Console
    from rich.table import Table

    table = Table(show_lines=False)
    for title in ("source", "decay", "angle deg", "duration s", "recording", "status"):
        table.add_column(title, overflow="fold")
    for decay in found.decays:
        table.add_row(
            str(decay.source), str(decay.index), f"{decay.initial_angle_deg:.2f}", f"{decay.duration_s:.1f}",
            decay.path.name, "written" if decay.added else "imported before",
        )  # fmt: skip
    console = Console(soft_wrap=False)
    if not console.is_terminal:  # a pipe or a file: every column whole
        console = Console(soft_wrap=False, width=240)
    console.print(table)
