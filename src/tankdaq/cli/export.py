"""``tankdaq export``: recordings to CSV, HDF5, Parquet or MATLAB .mat for the tools labs use."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..config import validation
from .app import app, checked, handles_errors, say


@app.command("export")
@handles_errors
def export_command(
    recordings: Annotated[
        list[Path],
        typer.Argument(
            callback=checked(validation.input_file),
            help="tankdaq recordings (.mcap), or a lab's files (an MT Manager .mtb, a TDMS, a CSV...): their "
            "decays become recordings in --out first (as tankdaq import makes them).",
        ),
    ],
    file_format: Annotated[
        str,
        typer.Option(
            "--format",
            help="csv (with a <name>.json of the run metadata), h5 (one file per decay), "
            "parquet (needs the parquet extra: pip install 'tankdaq[parquet]') or mat.",
        ),
    ] = "csv",
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            callback=checked(validation.output_dir),
            help="Folder for the files (default: beside each). Existing files are never overwritten: a "
            "file of an export's name there is refused (move it first), and so are two recordings of one "
            "name into one folder.",
        ),
    ] = None,
    frame: Annotated[
        str,
        typer.Option(
            "--frame", help="Time origin: release (t = 0 at the release) or device (the sensor clock)."
        ),
    ] = "release",
) -> None:
    """Write time, angle, rate and every recorded channel in SI units (units in the column names:
    time_s, roll_rad, p_rad_s, ...) with the run metadata as typed values, exactly as recorded.
    pandas, Excel and MATLAB read the CSV without options; tankdaq identify reads it back exactly.
    Prints each file written."""
    from ..api.archive import import_file
    from ..store.export import check_options, check_targets, export_recording
    from ..store.inputs import input_format

    check_options(file_format, frame)
    lab_files = [path for path in recordings if path.suffix.lower() != ".mcap"]
    for path in lab_files:
        input_format(path)  # a file tankdaq does not read: one line before any is written
    for path in lab_files:
        made = import_file(path, out or path.parent).decays
        say(f"{path}: {len(made)} decay(s) as recordings first: {', '.join(d.path.name for d in made)}")
        recordings = [*recordings, *(decay.path for decay in made)]
    recordings = [path for path in recordings if path not in lab_files]
    check_targets(recordings, file_format, out)
    for path in recordings:
        for written in export_recording(path, file_format, out, frame, on_notice=say):
            typer.echo(str(written))
