"""The kernels built ahead of time (``ident.compiled``, issue 14: replay >= 20x real time with start-up).

The native module must compute what numba's JIT computes, must not crash on a wrong argument, and
must be what a replay runs on: a ``tankdaq replay`` process imports no numba. A replay that cannot
build it still replays, on the JIT, with the same fit, and says why in one line.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tankdaq.ident import compiled, kernels


@pytest.fixture(scope="module")
def native() -> object:
    """The native module of this kernel source (``make test``'s prepare built it; else built here)."""
    assert compiled.ensure_native() is None, "the native kernels could not be built here"
    module = compiled.load_native(compiled.native_path())
    assert module is not None
    return module


@pytest.mark.slow
def test_the_native_kernels_compute_what_the_jit_computes(native: object) -> None:
    calls = compiled.example_calls()
    assert set(calls) == set(compiled.KERNELS)
    for name, args in calls.items():
        from_native = getattr(native, name)(*args)
        from_jit = getattr(kernels, name)(*args)
        pairs = (
            zip(from_native, from_jit, strict=True)
            if isinstance(from_jit, tuple)
            else [(from_native, from_jit)]
        )
        for got, want in pairs:
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=0, err_msg=name)
    angle = native.simulate(*calls["simulate"])[0]
    assert angle.size == 1500 and np.ptp(angle) > 0.1  # a real decay was compared, not zeros


@pytest.mark.slow
def test_a_wrong_argument_is_a_type_error_not_a_crash(native: object) -> None:
    """The native module does not check types (a list where it wants an array would crash the process)."""
    compiled.use_native(compiled.native_path())
    assert compiled.ahead_of_time()
    t = np.arange(200) / 100.0
    as_arrays = compiled.simulate(
        t, 0.1, 0.0, np.array([0.2, 9.0]), compiled.term_codes(["b1", "c1"]), 0 * t, 0.0, 1
    )
    as_lists = compiled.simulate(list(t), 0.1, 0, [0.2, 9], [0, 3], [0.0] * 200, 0, 1)  # ints and lists too
    np.testing.assert_array_equal(as_arrays[0], as_lists[0])
    with pytest.raises(TypeError, match="1-d array"):
        compiled.simulate(t[None, :], 0.1, 0.0, np.array([0.2, 9.0]), np.array([0, 3]), 0 * t, 0.0, 1)
    with pytest.raises(TypeError, match="takes 8 arguments"):
        compiled.simulate(t, 0.1)


#: ``tankdaq replay``, then which of the heavy start-up libraries the process had imported.
REPLAY = """
import atexit, sys
heavy = {"numba", "scipy.optimize"}
atexit.register(lambda: print("loaded:", sorted(heavy & set(sys.modules)), file=sys.stderr))
from tankdaq.cli import main
main()
"""


def _replay(path: Path, kernel_dir: str | None) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    if kernel_dir is not None:
        env["TANKDAQ_KERNEL_DIR"] = kernel_dir
    return subprocess.run(
        [sys.executable, "-c", REPLAY, "replay", str(path), "--speed", "max", "--viewer", "none"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )


def _fit_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if "b1=" in line]


@pytest.mark.slow
def test_a_replay_runs_on_the_native_kernels_without_numba(native: object, decay_recording: Path) -> None:
    done = _replay(decay_recording, None)
    assert done.returncode == 0, done.stderr
    assert len(_fit_lines(done.stdout)) == 1, done.stdout
    assert "loaded: []" in done.stderr, done.stderr


@pytest.mark.slow
def test_a_replay_that_cannot_build_the_kernels_uses_the_jit_says_why_and_fits_the_same(
    native: object, decay_recording: Path, tmp_path: Path
) -> None:
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("a file where the kernel folder would be: the build cannot write there\n")
    on_jit = _replay(decay_recording, str(blocked))
    on_native = _replay(decay_recording, None)
    assert on_jit.returncode == 0, on_jit.stderr
    said = on_jit.stdout + on_jit.stderr
    assert "numba's JIT" in said and "not-a-folder" in said, said
    assert "Traceback" not in said
    assert "'numba'" in on_jit.stderr  # it did run on the JIT
    assert _fit_lines(on_jit.stdout) == _fit_lines(on_native.stdout) != []


@pytest.mark.slow
def test_a_build_without_a_c_compiler_falls_back_and_is_not_retried(tmp_path: Path) -> None:
    """No working C compiler (CC=/bin/false): the JIT serves, the reason is kept, the next run does not
    try again and says how to make it."""
    env = {**os.environ, "TANKDAQ_KERNEL_DIR": str(tmp_path), "CC": "/bin/false"}
    probe = [
        sys.executable,
        "-c",
        "from tankdaq.ident import compiled as c; print(c.ensure_native()); print(c.ahead_of_time())",
    ]
    first = subprocess.run(probe, env=env, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    reason, native = first.stdout.strip().splitlines()
    assert native == "False" and reason != "None" and "compiler" in reason, first.stdout
    (note,) = tmp_path.glob("tankdaq_kernels-*.failed")
    assert not list(tmp_path.glob("tankdaq_kernels-*.so"))
    again = subprocess.run(probe, env=env, capture_output=True, text=True, timeout=300)
    said, native = again.stdout.strip().splitlines()
    assert native == "False" and said.startswith(reason) and f"delete {note} to retry" in said, said


@pytest.mark.slow  # a process of its own tries each module
def test_a_built_module_that_does_not_run_here_is_refused_before_it_is_used(tmp_path: Path) -> None:
    """A module that dies on this CPU (an illegal instruction) must fail the build, not a recording."""
    broken = tmp_path / f"{compiled.MODULE_NAME}.so"
    broken.write_bytes(b"\x7fELF not really a shared object")
    with pytest.raises(RuntimeError, match="does not run on this CPU"):
        compiled.check_runs_here(broken)
    compiled.check_runs_here(compiled.native_path())  # the module in use passes the same trial


@pytest.mark.slow
def test_a_kernel_warmed_by_prepare_is_loaded_from_the_cache_by_a_call_not_compiled_again(
    tmp_path: Path,
) -> None:
    """``make test`` warms the JIT in one process so that the workers load it: a call in a new process must
    find the code ``warm_jit`` filed (it was filed under the signature, a call looks for its arguments)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    warm = "from tankdaq.ident.compiled import warm_jit; warm_jit(['term_matrix'])"
    subprocess.run([sys.executable, "-c", warm], env=env, check=True, timeout=300)
    call = (
        "from tankdaq.ident import compiled, kernels; "
        "kernels.term_matrix(*compiled.example_calls()['term_matrix']); "
        "s = kernels.term_matrix.stats; print(sum(s.cache_hits.values()), sum(s.cache_misses.values()))"
    )
    done = subprocess.run([sys.executable, "-c", call], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["1", "0"], "the call compiled the kernel again instead of loading it"
