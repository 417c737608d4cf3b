"""``tankdaq recover``: turn a recording cut short (killed writer, full disk) into a valid MCAP file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..config import validation
from .app import app, checked, err_console, handles_errors


@app.command("recover")
@handles_errors
def recover_command(
    file: Annotated[Path, typer.Argument(help="The damaged recording (.mcap).")],
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            callback=checked(validation.output_file),
            help="Where to write the repaired file (default: NAME.recovered.mcap).",
        ),
    ] = None,
) -> None:
    """Rebuild a truncated recording. Exit 0: nothing lost; 3: damaged tail dropped; 1: nothing recovered."""
    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TimeRemainingColumn

    from ..store.recover import recover

    columns = (TextColumn("recovering"), BarColumn(), DownloadColumn(), TimeRemainingColumn())
    progress = Progress(*columns, console=err_console, transient=True)
    task = progress.add_task("recover", total=None)

    def advance(done: int, total: int) -> None:
        progress.start()  # only once reading has begun: a refused file gets its error line alone
        progress.update(task, completed=done, total=total)

    try:
        report = recover(file, out, progress=advance)
    finally:
        if progress.live.is_started:
            progress.stop()
    typer.echo(report.summary())
    raise typer.Exit(report.exit_code)
