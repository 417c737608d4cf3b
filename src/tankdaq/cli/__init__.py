"""Command-line interface: ``tankdaq <command>``; one module per room registers its commands."""

from __future__ import annotations

import os

# tankdaq's linear algebra is many small problems: BLAS threads only add start-up and contention
# (a 0.4 ms QR took 38 ms on a loaded 2-core machine). Set before numpy is first imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# each module registers its commands on ``app``; this order is the order of ``tankdaq --help``
# isort: off
from . import record  # noqa: F401  (record, replay, demo)
from . import simulate  # noqa: F401
from . import decode  # noqa: F401
from . import store  # noqa: F401  (recover)
from . import export  # noqa: F401
from . import identify  # noqa: F401
from . import campaign  # noqa: F401
from . import session  # noqa: F401
from . import diagnose  # noqa: F401
from . import auv  # noqa: F401
from . import hulls  # noqa: F401
# isort: on
from .app import app


def main() -> None:
    """Console-script entry point."""
    app()


__all__ = ["app", "main"]
