"""``tankdaq hulls``: what hull configurations exist and what they hold."""

from __future__ import annotations

import typer

from ..config import format_draft, list_hulls, load_hull
from .app import app, handles_errors


@app.command("hulls")
@handles_errors
def hulls_command(name: str = typer.Argument(None, help="Show one hull in full.")) -> None:
    """List the hulls in configs/hulls (axes, drafts, main dimensions)."""
    names = [name] if name else list_hulls()
    for hull_name in names:
        hull = load_hull(hull_name)
        typer.echo(f"{hull.name}: {hull.description}")
        for axis, model in sorted(hull.axes.items()):
            drafts = ", ".join(format_draft(d) for d in sorted(model.drafts))
            typer.echo(f"  {axis}: drafts {drafts}")
            if name:
                for d in sorted(model.drafts):
                    coeffs = "  ".join(f"{k}={v:g}" for k, v in model.drafts[d].items())
                    typer.echo(f"    {format_draft(d):>5}: {coeffs}")
        if name:
            for key, value in hull.dimensions.items():
                typer.echo(f"  {key} = {value:g}")
