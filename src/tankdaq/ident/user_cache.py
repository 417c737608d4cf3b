"""Where tankdaq keeps what it compiles on a user's machine: the user cache folder, never site-packages.

A pip install may be read-only (a lab PC's system-wide install, a container), so the native kernels
(``ident.compiled``) and numba's JIT cache of every ``cache=True`` kernel (``ident.kernels``,
``auv.model``) go to ``$TANKDAQ_CACHE_DIR``, else the platform's user cache folder
(``~/.cache/tankdaq`` on Linux, platformdirs). numba on its own would write beside the source first.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

#: tankdaq's own package folder: numba caches the kernels defined under it in the user cache.
PACKAGE_FOLDER = Path(__file__).resolve().parents[1]


def cache_folder() -> Path:
    """``$TANKDAQ_CACHE_DIR``, else the user cache folder for tankdaq (``~/.cache/tankdaq`` on Linux)."""
    env = os.environ.get("TANKDAQ_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("tankdaq", appauthor=False))


def shown(path: Path) -> str:
    """A folder as a person reads it: ``~/.cache/tankdaq`` rather than the home folder spelt out."""
    home = Path.home()
    return f"~/{path.relative_to(home)}" if path.is_relative_to(home) and path != home else str(path)


def numba_cache_folders() -> tuple[Path, ...]:
    """Where numba caches tankdaq's JIT kernels: the user cache, else (not writable) a private temp folder.

    The temp folder keeps the JIT working with a read-only home and a read-only install, where numba
    would otherwise refuse to compile any ``cache=True`` function at import.
    """
    user = os.environ.get("USER") or str(os.getuid() if hasattr(os, "getuid") else "user")
    return cache_folder() / "numba", Path(tempfile.gettempdir()) / f"tankdaq-{user}" / "numba"


def use_user_cache_for_numba() -> None:
    """Make numba cache tankdaq's ``cache=True`` kernels in the user cache (call before decorating them).

    numba picks a cache folder per function when it is decorated, from its list of locators; one more
    locator first in that list takes the functions defined in tankdaq's own files and leaves every
    other function (a user's notebook) to numba's usual places. ``NUMBA_CACHE_DIR``, when set, still wins.
    """
    from numba.core import caching

    locators: list[type[object]] = caching.CacheImpl._locator_classes  # the same in numba 0.61 to 0.68
    if any(cls.__name__ == "TankdaqCacheLocator" for cls in locators):
        return

    class TankdaqCacheLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
        def __init__(self, py_func: Any, py_file: str, folder: Path) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = str(folder / self.get_suitable_cache_subpath(py_file))

        def get_cache_path(self) -> str:
            return self._cache_path

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> TankdaqCacheLocator | None:
            ours = Path(py_file).resolve().is_relative_to(PACKAGE_FOLDER)
            if os.environ.get("NUMBA_CACHE_DIR") or not ours:
                return None
            for folder in numba_cache_folders():
                locator = cls(py_func, py_file, folder)
                try:
                    locator.ensure_cache_path()
                except OSError:
                    continue
                return locator
            return None

    locators.insert(0, TankdaqCacheLocator)
