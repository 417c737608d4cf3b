"""Files tankdaq hands to people (exports, reports, figures), written so that nothing a user wrote is
ever overwritten and no half-written file ever stands under a final name.

Each file is written to a temporary name in its own folder (``.<stem>.tmp-<random><suffix>``, the
suffix kept for writers that choose a format by it), flushed and fsynced, then published with
``os.link(temporary, final)``: the link fails when the final name exists, however late it appeared, so
no check-then-write race can overwrite a file. The temporary name is removed whatever happens. On a
file system without hard links (FAT, some network shares) the rename is made after looking once more.

The rule, said in the help of ``export`` and of every ``--report``: a final name that exists (a file,
a folder, a symbolic link, which is never followed) is refused in one line (``validation.
refuse_existing``, ``InputError``, exit 2), before any work where the caller knows its names; a failure
while writing (a full disk) is one line (``RecordingError``, exit 1) and leaves nothing behind.
"""

from __future__ import annotations

import csv
import errno
import io
import os
import secrets
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any, BinaryIO

from ..config.validation import NEVER_OVERWRITES, refuse_existing
from ..errors import InputError, RecordingError

__all__ = ["new_path", "refuse_existing", "write_new", "write_text_new"]
#: Errors of ``os.link`` that mean "this file system has no hard links", not "cannot write".
_NO_HARD_LINKS = frozenset(
    {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK, errno.ENOSYS, errno.EXDEV}
)
_TEMPORARY_MARK = ".tmp-"


@contextmanager
def new_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` for a writer that takes a path; when the block ends without an
    error it is fsynced and published under ``path``. Refused when ``path`` exists (also when it appears
    while the block runs); any error removes the temporary file, and an ``OSError`` becomes one line."""
    path = Path(path)
    refuse_existing([path])
    temporary = path.with_name(f".{path.stem}{_TEMPORARY_MARK}{secrets.token_hex(4)}{path.suffix}")
    try:
        yield temporary
        _fsync(temporary, os.O_RDWR)
        _publish(temporary, path)
    except OSError as exc:
        raise RecordingError(
            f"cannot write {path}: {exc.strerror or exc}; nothing was left under that name"
        ) from None
    finally:
        with suppress(OSError):
            temporary.unlink()


def write_new(path: str | Path, write: Callable[[BinaryIO], object]) -> Path:
    """Write a new file at ``path`` through ``write(binary file)`` (``new_path``'s rules); return it."""
    with new_path(path) as temporary:
        flags = (
            os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
        )
        with os.fdopen(os.open(temporary, flags, 0o644), "wb") as out:
            write(out)
    return Path(path)


def write_text_new(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """A new text file at ``path`` (``new_path``'s rules), newlines as written."""
    return write_new(path, lambda out: out.write(text.encode(encoding)))


def write_rows(rows: Sequence[Mapping[str, Any]], path: str | Path) -> Path:
    """Rows as a new CSV file, columns in first-seen order (a row without a column leaves it empty)."""
    columns = list(dict.fromkeys(k for row in rows for k in row))
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=columns, restval="")
    writer.writeheader()
    writer.writerows(rows)
    return write_text_new(path, text.getvalue())


def _fsync(path: Path, flags: int) -> None:
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _publish(temporary: Path, path: Path) -> None:
    """``temporary`` under ``path``: a hard link, which never replaces a file (no race); a rename where
    the file system has no hard links, after looking once more."""
    try:
        os.link(temporary, path)
    except FileExistsError:
        raise InputError(f"{path} appeared while it was written: {NEVER_OVERWRITES}") from None
    except OSError as exc:
        if exc.errno not in _NO_HARD_LINKS:
            raise
        refuse_existing([path])
        os.replace(temporary, path)
    if os.name != "nt":  # the new name itself survives a power cut (Windows cannot open a folder)
        _fsync(path.parent, os.O_RDONLY)
