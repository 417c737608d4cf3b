"""``tankdaq export``: recordings to CSV or MATLAB .mat for other labs' tools."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .. import validation
from .app import app, checked, handles_errors, say


@app.command("export")
@handles_errors
def export_command(
    recordings: Annotated[
        list[Path],
        typer.Argument(callback=checked(validation.input_file), help="tankdaq recordings (.mcap)."),
    ],
    file_format: Annotated[str, typer.Option("--format", help="csv or mat.")] = "csv",
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            callback=checked(validation.output_dir),
            help="Folder for the files (default: beside each).",
        ),
    ] = None,
    frame: Annotated[
        str, typer.Option("--frame", help="Time origin: device (the sensor clock) or release (t = 0 there).")
    ] = "device",
) -> None:
    """Write time, angle, rate and every recorded channel in SI units, with a units row and the run
    metadata (a comment block in CSV, a struct in .mat). tankdaq identify reads the CSV back exactly."""
    from ..errors import InputError
    from ..store.export import FRAMES, WRITERS, export_recording

    if file_format not in WRITERS:
        raise InputError(f"format {file_format!r} not understood: use {' or '.join(WRITERS)}")
    if frame not in FRAMES:
        raise InputError(f"frame {frame!r} not understood: use {' or '.join(FRAMES)}")
    for path in recordings:
        if path.suffix.lower() != ".mcap":
            raise InputError(f"{path}: not a tankdaq recording (.mcap)")
    for path in recordings:
        typer.echo(str(export_recording(path, file_format, out, frame, on_notice=say)))
