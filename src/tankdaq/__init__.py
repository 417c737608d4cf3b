"""tankdaq: towing-tank decay-test acquisition with live identification.

Data flows one way: serial bytes -> frames (xsens) -> samples -> decays (acquire)
-> fits (ident) -> views and files (viz, store). Every stage is usable from Python.

The public API (docs/api.md)::

    import tankdaq

    rec = tankdaq.read("run.mcap")            # .samples: a DataFrame, units in the column names
    result = tankdaq.identify(rec)            # .coefficients, .derived, .warnings, .plot()
    (sim,) = tankdaq.simulate("sim")          # a simulated decay written as a recording

Whatever ``__all__`` does not name is internal. The names load on first use, so ``import tankdaq``
(and ``tankdaq --help``) import no pandas, scipy or matplotlib.
"""

from __future__ import annotations

import importlib
import sys
import types

from ._version import __version__

TYPE_CHECKING = (
    False  # not ``typing``'s: importing typing was most of ``import tankdaq`` (mypy knows the name)
)

__all__ = [
    "Campaign",
    "Decay",
    "Diagnosis",
    "Identification",
    "ModelComparison",
    "Reading",
    "Recording",
    "Report",
    "__version__",
    "campaign",
    "compare_models",
    "diagnose",
    "docs",
    "identify",
    "import_archive",
    "make_report",
    "read",
    "runs",
    "set_reference",
    "simulate",
]

#: Public name -> the module that holds it.
_PUBLIC = {
    "read": "api.recording",
    "Recording": "api.recording",
    "Decay": "api.recording",
    "identify": "api.identification",
    "Identification": "api.identification",
    "Reading": "api.identification",
    "campaign": "api.campaigns",
    "compare_models": "api.comparison",
    "ModelComparison": "api.comparison",
    "Campaign": "api.campaigns",
    "diagnose": "api.diagnosis",
    "Diagnosis": "api.diagnosis",
    "simulate": "api.workflows",
    "docs": "api.pages",
    "runs": "catalogue.query",
    "set_reference": "catalogue.fits",
    "make_report": "report.make",
    "import_archive": "catalogue.archive",
    "Report": "report.make",
}

if TYPE_CHECKING:
    from typing import Any

    from .api.campaigns import Campaign, campaign
    from .api.comparison import ModelComparison, compare_models
    from .api.diagnosis import Diagnosis, diagnose
    from .api.identification import Identification, Reading, identify
    from .api.pages import docs
    from .api.recording import Decay, Recording, read
    from .api.workflows import simulate
    from .catalogue.archive import import_archive
    from .catalogue.fits import set_reference
    from .catalogue.query import runs
    from .report.make import Report, make_report


def __getattr__(name: str) -> Any:
    """The public names, imported when first asked for (PEP 562)."""
    if name not in _PUBLIC:
        raise AttributeError(f"module 'tankdaq' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_PUBLIC[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


class _Package(types.ModuleType):
    """``tankdaq`` itself. Importing a subpackage binds it as an attribute of its parent; the API's
    ``tankdaq.diagnose`` (the function) shares its name with the ``tankdaq.diagnose`` room, so a public
    name is never rebound to a module: the room stays reachable by ``from tankdaq.diagnose import ...``."""

    def __setattr__(self, name: str, value: object) -> None:
        if name in _PUBLIC and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
