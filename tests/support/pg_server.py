"""A throwaway PostgreSQL server for the catalogue's tests and bench: ``initdb`` and ``pg_ctl`` in a
temporary folder on a free port, stopped and removed at the end (as the ``postgres`` user when run as
root: initdb refuses root)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def why_not() -> str | None:
    """Why no server can be started here (None: it can)."""
    if not sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl")):
        return "PostgreSQL server binaries (initdb, pg_ctl) not installed: `make test` installs postgresql"
    if os.geteuid() == 0 and shutil.which("runuser") is None:
        return "running as root without runuser: initdb refuses root"
    return None


@contextmanager
def throwaway_postgres(password: str | None = None) -> Iterator[str]:
    """The server's URL (``postgresql://tankdaq@127.0.0.1:PORT/postgres``): trust authentication, or
    with ``password`` the role's password asked (scram-sha-256) and left out of the URL."""
    bin_dir = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"))[-1].parent
    folder = Path(tempfile.mkdtemp(prefix="tankdaq-pg-"))
    as_user: list[str] = []
    if os.geteuid() == 0:
        as_user = ["runuser", "-u", "postgres", "--"]
        shutil.chown(folder, "postgres")
    data, port = folder / "data", free_port()
    initdb = [
        *as_user,
        str(bin_dir / "initdb"),
        "-D",
        str(data),
        "-U",
        "tankdaq",
        "--auth=trust" if password is None else "--auth=scram-sha-256",
        "-E",
        "UTF8",
    ]
    if password is not None:
        (folder / "pwfile").write_text(password + "\n")
        if as_user:
            shutil.chown(folder / "pwfile", "postgres")
        initdb.append(f"--pwfile={folder / 'pwfile'}")
    pg_ctl = [*as_user, str(bin_dir / "pg_ctl"), "-D", str(data)]
    options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1"
    try:
        subprocess.run(initdb, check=True, capture_output=True, timeout=120)
        start = [*pg_ctl, "-o", options, "-l", str(folder / "log"), "-w", "start"]
        subprocess.run(start, check=True, capture_output=True, timeout=120)
        try:
            yield f"postgresql://tankdaq@127.0.0.1:{port}/postgres"
        finally:
            subprocess.run(
                [*pg_ctl, "-m", "fast", "-w", "stop"], check=True, capture_output=True, timeout=120
            )
    finally:
        shutil.rmtree(folder, ignore_errors=True)
