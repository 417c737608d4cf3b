"""The catalogue written as work happens, never in the way of a file.

``CatalogueWriter`` runs every write on a thread of its own, after the file it describes is closed:
a locked SQLite file waits out its busy timeout there, not in the record loop. A failure (locked,
corrupt, a server that does not answer) is one line, said once; the files are untouched and
``tankdaq catalogue index FOLDER`` catches up. ``session_listener`` hears a guided session's verdicts;
the record pipeline's listener is ``catalogue.sink.CatalogueSink``.
"""

from __future__ import annotations

import functools
import queue
import threading
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from .database import (
    WRITER_CACHE_KB,
    Catalogue,
    CatalogueError,
    describe,
    one_line,
    open_catalogue,
    resolve_url,
)
from .location import scrub

if TYPE_CHECKING:  # the session's module is imported by the session command only
    from ..campaign.stream import FileWork
    from ..session.state import RunEntry
    from .writing import Made

Job = Callable[[Catalogue], object]
#: How long a command waits at its end for the catalogue's last writes before it leaves them to index.
CLOSE_WAIT_S = 60.0
CATCH_UP = "the files are kept; `tankdaq catalogue index FOLDER` catches up"
#: A campaign's group fits (and the rows its workers made) go to the catalogue this many to a transaction.
CAMPAIGN_BATCH = 200
#: How long a campaign waits, before its scan, for the catalogue to say which files it lacks.
ASK_WAIT_S = 10.0


class CatalogueWriter:
    """Writes queued jobs to the catalogue at ``url`` (None: off, every job dropped) on one thread."""

    def __init__(self, url: str | None, on_line: Callable[[str], None]) -> None:
        self.url = url
        self.on_line = on_line
        self.failures: list[str] = []
        self._jobs: queue.Queue[tuple[Job, Future[object]] | None] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._catalogue: Catalogue | None = None
        self._closing = False
        self._campaign: list[
            tuple[list[tuple[Path, str | None]], dict[str, Any]]
        ] = []  # fits not yet handed to the thread
        self._rows: list[Made] = []  # rows made by a campaign's workers, not yet handed to the thread

    @classmethod
    def from_option(cls, given: str | None, on_line: Callable[[str], None]) -> CatalogueWriter:
        """From ``--catalogue`` (None: ``TANKDAQ_CATALOGUE`` or the user data folder); a value that is
        not a catalogue is refused before any work starts (``BadCatalogueQuery``)."""
        return cls(resolve_url(given), on_line)

    @property
    def enabled(self) -> bool:
        return self.url is not None

    def submit(self, job: Job) -> Future[object]:
        """Queue a write; it runs after the ones before it. Its future holds what it returned, or why
        it failed (said once as a line too); off, it is None at once."""
        done: Future[object] = Future()
        if self.url is None:
            done.set_result(None)
            return done
        if self._thread is None:
            self._thread = threading.Thread(target=self._serve, name="tankdaq-catalogue", daemon=True)
            self._thread.start()
        self._jobs.put((job, done))
        return done

    def _serve(self) -> None:
        while (item := self._jobs.get()) is not None:
            job, done = item
            try:
                if self._catalogue is None:
                    assert self.url is not None
                    self._catalogue = open_catalogue(self.url, WRITER_CACHE_KB)
                done.set_result(job(self._catalogue))
            except Exception as exc:
                done.set_exception(exc)
                self._fail(exc)
        if self._catalogue is not None:
            self._catalogue.close()

    def _fail(self, exc: BaseException) -> None:
        why = scrub(str(exc) if isinstance(exc, CatalogueError) else one_line(exc), self.url)
        if why not in self.failures:
            self.failures.append(why)
            self.on_line(f"catalogue: {why}; {CATCH_UP}")

    def close(self, wait_s: float = CLOSE_WAIT_S) -> None:
        """Let the queued writes finish (at most ``wait_s``), then stop the thread."""
        self._flush_campaign()
        if self._thread is None:
            return
        if not self._closing:
            self._closing = True
            self._jobs.put(None)
        self._thread.join(wait_s)
        if self._thread.is_alive():  # kept: a later close() may wait for it again
            assert self.url is not None
            self.on_line(f"catalogue: {describe(self.url)} still busy after {wait_s:g} s; {CATCH_UP}")
            return
        self._thread, self._closing = None, False

    def __enter__(self) -> CatalogueWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- what the commands write ----------------------------------------

    def add_files(self, paths: Iterable[Path]) -> None:
        from .writing import add_file

        for path in paths:
            self.submit(functools.partial(add_file, path=path))

    def add_fit(self, files: Iterable[tuple[Path, str | None]], fit: dict[str, Any]) -> None:
        """Keep ``fit`` on the rows of the bytes it read: each file with the SHA-256 of what was read
        (``writing.run_files``)."""
        from .writing import update_fit

        listed = list(files)
        self.submit(lambda catalogue: update_fit(catalogue, listed, fit))

    def add_session(self, folder: Path, only: str | None = None) -> None:
        from .writing import record_session

        self.submit(lambda catalogue: record_session(catalogue, folder, only))

    def add_campaign(self, results: Iterable[Any]) -> None:
        """A campaign's group fits: each made into its files and columns now (so the caller lets the
        fit and its runs go), written ``CAMPAIGN_BATCH`` groups to a transaction (the rest at close)."""
        from .writing import campaign_fit

        if self.url is None:
            return
        try:
            self._campaign += [fit for result in results if (fit := campaign_fit(result)) is not None]
        except Exception as exc:  # the catalogue's trouble, never the campaign's
            self._fail(exc)
        if len(self._campaign) >= CAMPAIGN_BATCH:
            self._flush_campaign()

    def _flush_campaign(self) -> None:
        """The rows the workers made, then the fits: a fit finds its file's row written."""
        if self.url is None:  # off: nothing was kept, nothing to import
            return
        from .writing import add_rows, update_fits

        rows, self._rows = self._rows, []
        if rows:
            self.submit(lambda catalogue: add_rows(catalogue, rows))
        batch, self._campaign = self._campaign, []
        if batch:
            self.submit(lambda catalogue: update_fits(catalogue, batch))

    def file_rows(self) -> FileWork:
        """A campaign's ``file_work``: the rows of the files this catalogue does not hold, made by the
        workers that scan them (``rows.worker_row``), so this process only writes them, ``CAMPAIGN_BATCH``
        to a transaction."""
        from ..campaign.stream import FileWork
        from .rows import worker_row

        return FileWork(self.uncatalogued, worker_row, self.add_rows)

    def uncatalogued(self, paths: Sequence[Path], wait_s: float = ASK_WAIT_S) -> list[Path]:
        """The decay files among ``paths`` with no row at their path, asked on the writer's thread; a
        catalogue that does not answer within ``wait_s`` (or fails: its one line) gives none, and the
        fits' write-back makes their rows as before."""
        from .writing import missing_paths

        if self.url is None:
            return []
        asked = self.submit(lambda catalogue: missing_paths(catalogue, paths))
        try:
            return cast("list[Path]", asked.result(timeout=wait_s))
        except Exception:  # a failure is said by the writer's thread; a timeout: none asked for
            return []

    def add_rows(self, made: Iterable[Made]) -> None:
        """Rows a campaign's workers made (``file_rows``), written ``CAMPAIGN_BATCH`` to a transaction
        before the fits that follow them."""
        if self.url is None:
            return
        self._rows += made
        if len(self._rows) >= CAMPAIGN_BATCH:
            self._flush_campaign()


def session_listener(writer: CatalogueWriter, folder: Path) -> Callable[[RunEntry], None]:
    """A guided session's verdict listener: the judged decay's row (and the session's) from its log."""

    def judged(entry: RunEntry) -> None:
        writer.add_session(folder, only=entry.file)

    return judged
