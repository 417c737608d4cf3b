"""Command-line interface: ``tankdaq <command>``; one module per room registers its commands."""

from __future__ import annotations

from . import hulls  # noqa: F401  (each import registers commands on ``app``)
from . import diagnose  # noqa: F401
from . import auv  # noqa: F401
from . import identify  # noqa: F401
from . import store  # noqa: F401
from . import campaign  # noqa: F401
from . import simulate  # noqa: F401
from . import decode  # noqa: F401
from . import record  # noqa: F401
from .app import app


def main() -> None:
    """Console-script entry point."""
    app()


__all__ = ["app", "main"]
