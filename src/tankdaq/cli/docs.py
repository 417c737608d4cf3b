"""``tankdaq docs [TOPIC]``: the documentation pages ``--help`` cites, printed from the installed copy."""

from __future__ import annotations

from typing import Annotated

import typer

from .app import app, handles_errors


@app.command("docs")
@handles_errors
def docs_command(
    topic: Annotated[
        str | None, typer.Argument(help="A page: catalogue, models, ... (docs/TOPIC.md); none lists them.")
    ] = None,
) -> None:
    """Print a documentation page (docs/TOPIC.md, shipped with tankdaq), or list the pages."""
    from ..api.pages import docs

    typer.echo(docs(topic))
