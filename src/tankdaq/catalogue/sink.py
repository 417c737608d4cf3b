"""The record pipeline's listener that files each closed decay in the catalogue.

Apart from ``hooks`` so that the commands that only write fits (identify, campaign, diagnose) do not load
the record pipeline.
"""

from __future__ import annotations

from ..acquire.decay import LiveDecay
from ..acquire.sinks import Sink
from .hooks import CatalogueWriter


class CatalogueSink(Sink):
    """A listener of the record pipeline: each decay's file, once closed, goes into the catalogue.

    It comes after the file's sink in the pipeline, so ``on_settle`` hears a closed file."""

    def __init__(self, writer: CatalogueWriter) -> None:
        self.writer = writer

    def on_settle(self, decay: LiveDecay) -> None:
        if decay.path is not None and decay.path.is_file():
            self.writer.add_files([decay.path])

    def close(self) -> None:
        """The writer outlives one pipeline (a session opens one per decay): its owner closes it."""
