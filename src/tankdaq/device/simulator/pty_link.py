"""The simulated device's cable: a pseudo-terminal the driver opens by path, like a USB serial port.

The link owns the master side of a pty (raw mode, slave kept open so reads never hit EIO) and
a temporary folder ``/tmp/tankdaq-sim-<random>`` (with ``owner.pid``) holding a stable symlink to
the pty and, like udev's ``/dev/serial/by-id``, a ``usb-Xsens_<product>_<serial>-if00-port0``
link, named in ``TANKDAQ_SERIAL_BY_ID`` while the link exists. Unplugging closes the pty (its
path and links vanish); plugging back opens a new pty under a new ``/dev/pts`` name behind the
same links. The pty has no speed: the slave's termios speed is what the host set, and bytes are
paced to the device's baud rate here; at the wrong speed the host reads garbage.

The folder goes on every exit path (``remove``, interpreter exit); one left by ``kill -9`` is
swept by the next link made (its owner process is dead). A stable link at a path the caller names
is never put over anything but a dead simulator's link (``link_refusal``), and only the link this
simulator made is removed.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import os
import pty
import shutil
import tempfile
import termios
import time
import tty
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..ports import BY_ID_ENV

#: Temporary folders of simulators: ``tankdaq-sim-<random>`` holding ``owner.pid``.
TEMP_PREFIX = "tankdaq-sim-"
OWNER_FILE = "owner.pid"
#: A device's output buffer: beyond it, data is lost (as on a link that is too slow). At ``speed`` times
#: the device's clock the buffer holds ``speed`` times as many bytes: a host that lags a given wall time
#: then loses data exactly when it would behind a real device (at 10x speed and 400 Hz the plain limit
#: was half a second of the wall's, which a loaded test machine's reader lagged).
OUTBOX_LIMIT = 1 << 18


def link_refusal(path: str | Path) -> str | None:
    """Why the simulator must not put its link at ``path``; None when nothing is there or only the
    link of a simulator that is gone (to a ``/dev/pts`` entry that no longer exists)."""
    path = str(path)
    if not os.path.lexists(path):
        return None
    if os.path.islink(path):
        target = os.readlink(path)
        if target.startswith("/dev/pts/") and not os.path.exists(target):
            return None
        return f"{path} is a link to {target}, not a simulator's: remove it or choose another path"
    return f"{path} exists and is not a simulator's link: choose another path (it is left untouched)"


def _remove_own_link(link: str, target: str) -> None:
    """Remove ``link`` only while it is still the link to ``target`` this simulator made."""
    with contextlib.suppress(OSError):
        if os.path.islink(link) and os.readlink(link) == target:
            os.unlink(link)


class PtyLink:
    """A pty behind a stable link and a by-id link; ``port`` is the current /dev/pts/N ("" unplugged)."""

    def __init__(self, by_id_name: str, link: str | Path | None = None, seed: int = 0) -> None:
        self._by_id_name = by_id_name
        self.link = str(link) if link else ""  # a temporary one is made by ``create``
        self.by_id_dir = ""
        self._by_id_link = ""
        self._own_dir: str | None = None
        self.port = ""
        self._last_port = ""
        self.master = -1
        self._slave = -1
        self._budget = 0.0
        self._budget_at = 0.0
        self._burst_at = 0.0  # when the last latency burst went out (wall clock)
        self._rng = np.random.default_rng([seed, 98])
        self.bytes_overflowed = 0

    def create(self) -> None:
        """Make the folder and its by-id entry (the pty itself opens with ``plug``); a link path given
        where something else is refuses (InputError) before anything is made."""
        if self.link and (why := link_refusal(self.link)) is not None:
            raise InputError(f"--link {why}")
        sweep_stale_folders()
        self._own_dir = tempfile.mkdtemp(prefix=TEMP_PREFIX)
        atexit.register(self.remove)
        Path(self._own_dir, OWNER_FILE).write_text(f"{os.getpid()}\n")
        self.by_id_dir = os.path.join(self._own_dir, "by-id")
        os.mkdir(self.by_id_dir)
        self._by_id_link = os.path.join(self.by_id_dir, self._by_id_name)
        register_by_id(self.by_id_dir)
        if not self.link:
            self.link = os.path.join(self._own_dir, "ttyMTi0")

    def remove(self) -> None:
        """Unplug and remove the folder (links, by-id, owner file); also runs at interpreter exit."""
        self.unplug()
        if self._own_dir:
            unregister_by_id(self.by_id_dir)
            shutil.rmtree(self._own_dir, ignore_errors=True)
            atexit.unregister(self.remove)
            self._own_dir = None

    @property
    def plugged(self) -> bool:
        return self.master >= 0

    def plug(self) -> None:
        """Open a pty (a re-plugged device comes back under a new name) and point the links at it."""
        if self.master >= 0:
            return
        master, slave = pty.openpty()
        if os.ttyname(slave) == self._last_port:
            held = (master, slave)
            master, slave = pty.openpty()
            for fd in held:
                os.close(fd)
        tty.setraw(slave)  # a cooked slave would echo and mangle the binary stream
        os.set_blocking(master, False)
        self.master, self._slave = master, slave
        self.port = self._last_port = os.ttyname(slave)
        for link in (self.link, self._by_id_link):
            tmp = f"{link}.new"
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            os.symlink(self.port, tmp)
            os.replace(tmp, link)
        self.restart_pacing()

    def unplug(self) -> None:
        """Close the pty; its path and the links (the ones it made, still pointing at it) vanish."""
        for link in (self.link, self._by_id_link):
            if link and self.port:
                _remove_own_link(link, self.port)
        for fd in (self.master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master = self._slave = -1

    def speed_matches(self, baud: int) -> bool:
        """True when the host set the pty to ``baud`` (pty speeds are only labels)."""
        if self._slave < 0:
            return False
        speed = termios.tcgetattr(self._slave)[5]
        wanted = getattr(termios, f"B{baud}", None)
        return wanted is None or speed == wanted

    def read(self) -> bytes:
        """What the host wrote (b"" when nothing is waiting)."""
        try:
            return os.read(self.master, 4096)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                return b""
            raise

    def restart_pacing(self) -> None:
        """A device that boots starts with an empty line."""
        self._budget, self._budget_at = 0.0, time.monotonic()

    def holding(self, latency_s: float) -> float:
        """Wall seconds until a USB adapter with latency timer ``latency_s`` hands its bytes over (0: now)."""
        return max(0.0, self._burst_at + latency_s - time.monotonic()) if latency_s > 0 else 0.0

    def send(self, outbox: bytearray, baud: int, speed: float, latency_s: float = 0.0) -> None:
        """Write from ``outbox`` what ``baud`` carries since the last write (``speed``: device clock
        speed-up); bytes beyond the device's buffer are lost, at the wrong line speed they are garbage.
        With ``latency_s`` (a USB adapter's latency timer) the bytes go in one burst per period."""
        limit = int(OUTBOX_LIMIT * max(1.0, speed))
        if len(outbox) > limit:
            excess = len(outbox) - limit
            del outbox[:excess]
            self.bytes_overflowed += excess
        if not outbox or self.master < 0 or self.holding(latency_s) > 0:
            return
        now = time.monotonic()
        bytes_per_s = baud / 10 * speed
        self._budget = min(self._budget + (now - self._budget_at) * bytes_per_s, max(bytes_per_s * 0.05, 256))
        self._budget_at = now
        n = min(len(outbox), int(self._budget))
        if n <= 0:
            return
        chunk = bytes(outbox[:n])
        if not self.speed_matches(baud):  # read at the wrong baud rate, every byte comes out garbled
            chunk = self._rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        try:
            written = os.write(self.master, chunk)
        except OSError:
            return  # nobody reads (or the pty went away): keep the bytes, the buffer limit applies
        del outbox[:written]
        self._budget -= written
        self._burst_at = now  # a USB adapter with a latency timer holds the next bytes a period


def register_by_id(folder: str) -> None:
    """Name ``folder`` in ``TANKDAQ_SERIAL_BY_ID`` so this process's port finder sees the device."""
    dirs = [d for d in os.environ.get(BY_ID_ENV, "").split(os.pathsep) if d]
    os.environ[BY_ID_ENV] = os.pathsep.join([*dirs, folder])


def unregister_by_id(folder: str) -> None:
    """Drop ``folder`` from ``TANKDAQ_SERIAL_BY_ID`` (the device it names is gone)."""
    dirs = [d for d in os.environ.get(BY_ID_ENV, "").split(os.pathsep) if d and d != folder]
    if dirs:
        os.environ[BY_ID_ENV] = os.pathsep.join(dirs)
    else:
        os.environ.pop(BY_ID_ENV, None)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_stale_folders(root: str | None = None) -> list[Path]:
    """Remove simulator folders whose owner process is dead (a kill -9 leaves them); returns them.

    Folders without an owner file are left alone (they may be being created right now).
    """
    removed = []
    for folder in Path(root or tempfile.gettempdir()).glob(f"{TEMP_PREFIX}*"):
        try:
            pid = int((folder / OWNER_FILE).read_text())
        except (OSError, ValueError):
            continue
        if not _pid_alive(pid):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed
