"""``tankdaq docs [TOPIC]``: the documentation pages ``--help`` cites, printed from the installed copy."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .app import app, handles_errors


@app.command("docs")
@handles_errors
def docs_command(
    topic: Annotated[
        str | None, typer.Argument(help="A page: catalogue, models, ... (docs/TOPIC.md); none lists them.")
    ] = None,
    examples: Annotated[
        Path | None,
        typer.Option(
            "--examples",
            metavar="DIR",
            help="Copy the example notebook and the docs' example files into DIR (a file there is refused).",
        ),
    ] = None,
) -> None:
    """Print a documentation page (docs/TOPIC.md, shipped with tankdaq), or list the pages."""
    from ..api.pages import copy_examples, docs

    if examples is not None:
        for path in copy_examples(examples):
            typer.echo(path)
        return
    typer.echo(docs(topic))
