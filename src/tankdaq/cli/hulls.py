"""``tankdaq hulls``: which hull files exist, where each came from; ``hulls new``/``hulls show``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated

import typer

from .app import app, handles_errors, say

if TYPE_CHECKING:  # the hull files are read by the commands: --help of every command skips config
    from ..config.hulls import Hull

hulls_app = typer.Typer(
    no_args_is_help=False,
    invoke_without_command=True,
    help="Hull files: list them with their origin (user folder or shipped), show one, write a template.",
)
app.add_typer(hulls_app, name="hulls")


@hulls_app.callback()
@handles_errors
def list_command(ctx: typer.Context) -> None:
    """List every hull found by name and where it came from (the user's folder shadows shipped ones)."""
    if ctx.invoked_subcommand is not None:
        return
    from ..config.hulls import find_hulls, load_hull, user_hulls_dir
    from ..errors import InputError

    typer.echo(f"user hull folder: {user_hulls_dir()} (set TANKDAQ_HULLS_DIR to move it)")
    skipped = 0
    for entry in find_hulls():
        try:
            hull = load_hull(str(entry.path))
        except InputError as exc:  # one bad file in the folder does not hide the others
            say(f"skipped: {exc}")
            skipped += 1
            continue
        hides = f"; hides the shipped {entry.shadows}" if entry.shadows else ""
        typer.echo(f"{entry.name}: {hull.description}")
        typer.echo(f"  from {entry.origin}: {entry.path}{hides}")
        typer.echo(f"  {_particulars_line(hull)}")
    if skipped:
        raise InputError(f"{skipped} hull file(s) skipped (each named above); fix or remove them")


def _particulars_line(hull: Hull) -> str:
    """GM per axis and which axes the simulator can play."""
    gm = ", ".join(f"GM {axis} {p.gm_m:g} m" for axis, p in sorted(hull.axes.items()) if p.gm_m is not None)
    simulated = ", ".join(sorted(hull.simulation)) or "none (a real model: record from a real port)"
    return f"{gm or 'no GM given'}; simulation: {simulated}"


@hulls_app.command("show")
@handles_errors
def show_command(name: Annotated[str, typer.Argument(help="Hull name or .toml path.")]) -> None:
    """Show one hull in full: origin, dimensions, GM and gyradius, simulation coefficients."""
    from ..config.hulls import format_draft, load_hull

    hull = load_hull(name)
    typer.echo(f"{hull.name}: {hull.description}")
    typer.echo(f"  from {hull.origin}: {hull.path}")
    for key, value in hull.dimensions.items():
        typer.echo(f"  {key} = {value:g}")
    for axis, p in sorted(hull.axes.items()):
        known = {"gm_m": p.gm_m, "radius_of_gyration_m": p.radius_of_gyration_m}
        typer.echo(f"  {axis}: " + "  ".join(f"{k}={v:g}" for k, v in known.items() if v is not None))
    if hull.main_particulars.values:
        typer.echo(
            "  particulars: " + "  ".join(f"{k}={v:g}" for k, v in hull.main_particulars.values.items())
        )
    for axis, model in sorted(hull.simulation.items()):
        typer.echo(f"  simulation {axis}:")
        for d in sorted(model.drafts):
            coeffs = "  ".join(f"{k}={v:g}" for k, v in model.drafts[d].items())
            typer.echo(f"    {format_draft(d):>5}: {coeffs}")


@hulls_app.command("new")
@handles_errors
def new_command(
    name: Annotated[str, typer.Argument(help="Name of the new hull (letters, digits, -).")],
) -> None:
    """Write a commented hull template to the user's hull folder; print it, then its path (the last line)."""
    from ..config.hulls import write_hull_template

    path = write_hull_template(name)
    typer.echo(path.read_text(), nl=False)  # what to edit, shown where the user is looking
    typer.echo(str(path))
