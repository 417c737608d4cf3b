"""What tankdaq compiles goes to the user cache folder, never beside its installed source (issue 23).

A pip install may be read-only: the native kernels and numba's JIT cache of tankdaq's own kernels go to
``$TANKDAQ_CACHE_DIR``, else platformdirs' user cache folder; a user's own numba functions keep numba's
usual places. Each check runs in a fresh interpreter, since where numba caches is decided at import.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

#: Prints where the native module would be built and where numba caches tankdaq's kernels and a user's.
WHERE = """
import json, sys
import numba
from tankdaq.ident import compiled, kernels
from tankdaq.auv import model
sys.path.insert(0, sys.argv[1])
import users_module
print(json.dumps({
    "kernels": str(compiled.kernel_folder()),
    "native": str(compiled.native_path()),
    "numba": kernels.simulate._cache._cache_path,
    "auv": model._rhs._cache._cache_path,
    "users": users_module.twice._cache._cache_path,
}))
"""

USERS_MODULE = "import numba\n\n@numba.njit(cache=True)\ndef twice(x):\n    return 2 * x\n"

#: Variables that would steer the folders: the child sees only the ones a test sets.
STEERING = ("TANKDAQ_CACHE_DIR", "TANKDAQ_KERNEL_DIR", "NUMBA_CACHE_DIR", "XDG_CACHE_HOME")


def _where(tmp_path: Path, **env: str) -> dict[str, str]:
    users = tmp_path / "users"
    users.mkdir(exist_ok=True)
    (users / "users_module.py").write_text(USERS_MODULE)
    child_env = {k: v for k, v in os.environ.items() if k not in STEERING} | env
    done = subprocess.run(
        [sys.executable, "-c", WHERE, str(users)], env=child_env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    return dict(json.loads(done.stdout))


@pytest.mark.slow
def test_kernels_and_numba_cache_go_to_the_user_cache_folder_and_a_users_numba_stays_put(
    tmp_path: Path,
) -> None:
    home = tmp_path / "home"
    where = _where(tmp_path, HOME=str(home))
    cache = home / ".cache" / "tankdaq"
    assert Path(where["kernels"]) == cache / "kernels"
    assert Path(where["native"]).parent == cache / "kernels"
    assert Path(where["numba"]).is_relative_to(cache / "numba"), where
    assert Path(where["auv"]).is_relative_to(cache / "numba"), where
    assert Path(where["users"]).is_relative_to(tmp_path / "users"), "a user's own numba cache moved"


@pytest.mark.slow
def test_tankdaq_cache_dir_chooses_the_folder(tmp_path: Path) -> None:
    chosen = tmp_path / "chosen"
    where = _where(tmp_path, HOME=str(tmp_path / "home"), TANKDAQ_CACHE_DIR=str(chosen))
    assert Path(where["kernels"]) == chosen / "kernels"
    assert Path(where["numba"]).is_relative_to(chosen / "numba"), where


@pytest.mark.slow
def test_an_unwritable_cache_leaves_the_jit_working_from_a_private_temp_folder(tmp_path: Path) -> None:
    """A cache folder that cannot be made (a file in its way: refused even to root): the native build
    fails with its reason, and numba still caches tankdaq's kernels (in a temp folder) instead of
    refusing to compile them at import."""
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder\n")
    temp = tmp_path / "temp"
    temp.mkdir()
    env = {"HOME": str(tmp_path / "home"), "TANKDAQ_CACHE_DIR": str(blocked / "cache"), "TMPDIR": str(temp)}
    where = _where(tmp_path, **env)
    assert Path(where["numba"]).is_relative_to(temp), where
    probe = "from tankdaq.ident import compiled as c; print(c.ensure_native()); print(c.ahead_of_time())"
    child_env = {k: v for k, v in os.environ.items() if k not in STEERING} | env
    done = subprocess.run(
        [sys.executable, "-c", probe], env=child_env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    reason, native = done.stdout.strip().splitlines()
    assert native == "False" and "a-file" in reason, done.stdout
