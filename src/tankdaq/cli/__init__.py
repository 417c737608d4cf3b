"""Command-line interface: ``tankdaq <command>``; one module per room registers its commands.

``tankdaq COMMAND ...`` imports only the module that registers COMMAND (``COMMAND_MODULES``): a command
and its ``--help`` do not pay for the other rooms' modules nor typer's building of their parameters.
``tankdaq --help``, an unknown command and ``from tankdaq.cli import app`` register every command.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import TYPE_CHECKING, Any

# tankdaq's linear algebra is many small problems: BLAS threads only add start-up and contention
# (on a loaded machine a small QR waits for its threads many times its own cost). Set before numpy is
# first imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from .app import app as _app

if TYPE_CHECKING:
    import typer

# ``app`` is served by ``__getattr__`` (every command registered); importing the submodule bound the name
del app  # type: ignore[name-defined]  # noqa: F821

#: The module that registers each command (a group counts as one), in the order of ``tankdaq --help``.
COMMAND_MODULES = {
    "record": "record",
    "replay": "record",
    "demo": "record",
    "simulate": "simulate",
    "device": "device",
    "decode": "decode",
    "recover": "store",
    "export": "export",
    "import": "archive",
    "identify": "identify",
    "campaign": "campaign",
    "simulate-campaign": "campaign",
    "session": "session",
    "diagnose": "diagnose",
    "predict": "predict",
    "report": "report",
    "auv": "auv",
    "hulls": "hulls",
    "catalogue": "catalogue",
    "runs": "catalogue",
    "docs": "docs",
}


def registered_app(command: str | None = None) -> typer.Typer:
    """The app with ``command``'s module imported, or every command module (None, or a name that no
    module registers: click then lists the commands it knows)."""
    module = COMMAND_MODULES.get(command or "")
    for name in [module] if module else dict.fromkeys(COMMAND_MODULES.values()):
        importlib.import_module(f"{__name__}.{name}")
    return _app


def __getattr__(name: str) -> Any:
    if name == "app":
        return registered_app()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def main() -> None:
    """Console-script entry point: only the module of the command asked for is imported; stdout and stderr
    write what their encoding cannot show as plain text (``cli.plain_text``)."""
    from .plain_text import install

    install()
    registered_app(sys.argv[1] if len(sys.argv) > 1 else None)()


__all__ = ["COMMAND_MODULES", "app", "main", "registered_app"]
