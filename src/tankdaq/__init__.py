"""tankdaq: towing-tank decay-test acquisition with live identification.

Data flows one way: serial bytes -> frames (xsens) -> samples -> decays (acquire)
-> fits (ident) -> views and files (viz, store). Every stage is usable from Python.
"""

__version__ = "0.1.0"


def __getattr__(name: str) -> object:
    """Lazy exports: ``tankdaq.runs`` (the run catalogue as a DataFrame) imports SQLAlchemy only when used."""
    if name == "runs":
        from .catalogue.query import runs

        return runs
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
