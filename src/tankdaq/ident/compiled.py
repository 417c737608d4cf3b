"""The identification kernels, loaded without numba when they have been built ahead of time.

Every fit runs the kernels whose numba source is ``ident.kernels``. Loading them through numba's
JIT costs about 0.8 s in every process (numba's import, then its first cached call, which imports
scipy.linalg for BLAS): more than a whole ``tankdaq replay`` of one decay may take. ``build``
compiles the same source ahead of time (numba.pycc) into one native module, named by a hash of
the kernel source and the signatures below: loading it takes about a millisecond and imports
nothing. ``python -m tankdaq.prepare`` (run by ``make``) or the first command that fits (record,
replay, identify, campaign, diagnose) builds it, into the user cache folder (``ident.user_cache``:
an install may be read-only). Where it cannot be built (no C compiler, a numba without pycc, no
writable cache) or is stale, numba's JIT serves the very same functions: slower to start, equal in
results (a test holds them equal).

The native module does not check its arguments (a list where it expects an array crashes the
process), so every kernel is called through a wrapper that converts each argument to the exact
dtype and checks its rank: a wrong call raises ``TypeError`` instead.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.machinery
import importlib.util
import math
import os
import platform
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from ..physics.terms import TERM_TABLE
from .user_cache import cache_folder

KERNEL_SOURCE = Path(__file__).with_name("kernels.py")
MODULE_NAME = "tankdaq_kernels"
#: How ``build`` compiles (``_pycc_as_the_jit``), part of the module's name: a module built the old
#: way (holding the interpreter lock, the CPU model's features) is never loaded again.
BUILD_SETTINGS = "release_gil host_features tried_in_a_child"

#: The native module's size on disk (0.81 MB on x86-64 Linux, numba 0.68), for the first run's notice.
NATIVE_SIZE_MB = 0.8

#: numba type of each argument kind, and how a call's argument is made exactly that.
ARGUMENT_KINDS: dict[str, tuple[str, Callable[[Any], Any]]] = {
    "vector": ("f8[::1]", lambda a: _array(a, np.float64, 1)),
    "matrix": ("f8[:, ::1]", lambda a: _array(a, np.float64, 2)),
    "cube": ("f8[:, :, ::1]", lambda a: _array(a, np.float64, 3)),
    "codes": ("i8[::1]", lambda a: _array(a, np.int64, 1)),
    "float": ("f8", float),
    "int": ("i8", int),
    "bool": ("b1", bool),
}

#: Every kernel a fit calls: its argument kinds and its numba return type (what the module exports).
KERNELS: dict[str, tuple[tuple[str, ...], str]] = {
    "simulate": (
        ("vector", "float", "float", "vector", "codes", "vector", "float", "int"),
        "Tuple((f8[:], f8[:]))",
    ),
    "simulate_with_sensitivities": (
        ("vector", "float", "float", "vector", "codes", "vector", "matrix", "float", "int"),
        "Tuple((f8[:], f8[:], f8[:, :], f8[:, :], b1))",
    ),
    "acceleration_partials": (
        ("codes", "vector", "vector", "vector", "vector", "float"),
        "Tuple((f8[:], f8[:], f8[:], f8[:], f8[:, :]))",
    ),
    "term_matrix": (("codes", "vector", "vector", "vector", "float"), "f8[:, :]"),
    "hac_meat": (("cube", "matrix", "matrix", "int", "bool"), "f8[:, :]"),
}


def _array(value: Any, dtype: type, rank: int) -> np.ndarray:
    array: np.ndarray = np.ascontiguousarray(value, dtype=dtype)
    if array.ndim != rank:
        raise TypeError(f"a kernel expected a {rank}-d array, got {array.ndim}-d")
    return array


def signature(name: str) -> str:
    """The numba signature the native module exports ``name`` with."""
    kinds, returns = KERNELS[name]
    return f"{returns}({', '.join(ARGUMENT_KINDS[kind][0] for kind in kinds)})"


def kernel_folder() -> Path:
    """Where the native module lives: ``TANKDAQ_KERNEL_DIR``, else ``kernels`` in the user cache folder."""
    return Path(os.environ.get("TANKDAQ_KERNEL_DIR") or cache_folder() / "kernels")


def cpu_identity() -> str:
    """The CPU's vendor, model and instruction-set flags where Linux tells them cheaply, else "".

    A native module tuned for this CPU must never load on another one (an install shared over
    NFS by different machines): the identity is part of its name, and without one the build is
    generic (its fits are about a quarter slower).
    """
    try:
        first_cpu = Path("/proc/cpuinfo").read_text().split("\n\n", 1)[0]
    except OSError:
        return ""
    wanted = ("vendor_id", "model name", "flags")
    return "\n".join(line for line in first_cpu.splitlines() if line.startswith(wanted))


def native_path(folder: Path | None = None) -> Path:
    """The native module's file for this kernel source, these signatures, numpy and CPU."""
    key = hashlib.sha256(KERNEL_SOURCE.read_bytes())
    key.update(repr([signature(name) for name in sorted(KERNELS)]).encode())
    key.update(f"{np.__version__} {platform.machine()} {cpu_identity()} {BUILD_SETTINGS}".encode())
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    return (folder or kernel_folder()) / f"{MODULE_NAME}-{key.hexdigest()[:16]}{suffix}"


def load_native(path: Path) -> ModuleType | None:
    """The native module at ``path``, or None where there is none or it does not load."""
    spec = importlib.util.spec_from_file_location(MODULE_NAME, path)
    if spec is None or spec.loader is None or not path.exists():
        return None
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except ImportError:
        return None
    return module


def build(folder: Path | None = None) -> Path:
    """Compile every kernel ahead of time into the native module (a C compiler is needed; ~20 s of CPU).

    Written under a temporary name, tried in a child process (a module that dies on this CPU raises
    ``RuntimeError`` here instead of killing a recording later) and only then renamed: a process
    loading it never sees half a file or an untried one.
    """
    from numba.pycc import CC  # numba only here, and where the native module is missing

    from . import kernels

    target = native_path(folder)
    target.parent.mkdir(parents=True, exist_ok=True)
    with (
        tempfile.TemporaryDirectory(dir=target.parent) as tmp,
        warnings.catch_warnings(),
        _pycc_as_the_jit(),
    ):
        warnings.simplefilter("ignore")  # pycc's pending deprecation: the JIT is the way back
        compiler = CC(MODULE_NAME)
        compiler.output_dir = tmp
        compiler.output_file = target.name
        compiler.target_cpu = "host" if cpu_identity() else ""
        for name in KERNELS:
            compiler.export(name, signature(name))(getattr(kernels, name).py_func)
        compiler.compile()
        check_runs_here(Path(tmp) / target.name)
        os.replace(Path(tmp) / target.name, target)
    return target


@contextlib.contextmanager
def _pycc_as_the_jit() -> Iterator[None]:
    """numba.pycc made to compile as the JIT does (``nogil=True`` and the host's own features), while
    ``build`` runs.

    pycc ignores the kernels' ``nogil``: its wrappers hold the interpreter lock for a whole call (a
    runaway refit then stopped the read loop and Ctrl-C). And for ``target_cpu="host"`` it takes
    every feature of the CPU model's name, not the host's: a virtual machine reporting an AMD
    ``znver4`` without AVX-512 got AVX-512 instructions (SIGILL at the first call). Both are fixed
    the way the JIT does it, on pycc's flags and its ahead-of-time code generator, put back after.
    """
    from numba.core import codegen
    from numba.pycc import compiler as pycc_compiler

    plain_flags = pycc_compiler.Flags
    model_features = codegen.AOTCPUCodegen._customize_tm_features

    class ReleasingFlags(plain_flags):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.release_gil = True

    def host_features(self: Any) -> str:
        return str(self._get_host_cpu_features()) if self._cpu_name == "host" else ""

    pycc_compiler.Flags = ReleasingFlags  # type: ignore[misc]
    codegen.AOTCPUCodegen._customize_tm_features = host_features  # type: ignore[method-assign]
    try:
        yield
    finally:
        pycc_compiler.Flags = plain_flags  # type: ignore[misc]
        codegen.AOTCPUCodegen._customize_tm_features = model_features  # type: ignore[method-assign]


def check_runs_here(path: Path) -> None:
    """Load ``path`` and run every kernel once in a child process; raise where that does not work."""
    script = (
        "import sys; from pathlib import Path; from tankdaq.ident import compiled as c; "
        "m = c.load_native(Path(sys.argv[1])); assert m is not None, 'it does not load'; "
        "[getattr(m, name)(*args) for name, args in c.example_calls().items()]"
    )
    child = subprocess.run(
        [sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=120, check=False
    )
    if child.returncode != 0:
        said = (child.stderr.strip().splitlines() or [f"exit status {child.returncode}"])[-1]
        raise RuntimeError(f"the native module built here does not run on this CPU ({said})")


def example_calls() -> dict[str, tuple[Any, ...]]:
    """One call of every kernel on a small made-up decay (the arguments exactly as the kernels take them).

    What a new build is tried with, and what the test holding native and JIT equal compares.
    """
    rng = np.random.default_rng(3)
    t = np.arange(1500) / 100.0
    u = 0.02 * np.sin(2.1 * t)
    du_dp = np.column_stack([np.sin(2.1 * t), np.cos(2.1 * t)])
    x = 0.2 * np.exp(-0.1 * t) * np.cos(3.7 * t)
    v = np.gradient(x, t)
    jac = rng.normal(size=(2, t.size, 9))
    residuals = rng.normal(size=(2, t.size))
    codes = term_codes(EXAMPLE_TERMS)
    theta = np.array(EXAMPLE_THETA)
    return {
        "simulate": (t, 0.2, 0.0, theta, codes, u, 0.02, 2),
        "simulate_with_sensitivities": (t, 0.2, 0.0, theta, codes, u, du_dp, 0.02, 2),
        "acceleration_partials": (codes, theta, x, v, u, 0.02),
        "term_matrix": (codes, x, v, u, 0.02),
        "hac_meat": (jac, residuals, np.eye(9) * 1e-3, 150, True),
    }


#: The example decay's terms and coefficients (every kind of term: damping, restoring, friction).
EXAMPLE_TERMS = ("b1", "b2", "b3", "c1", "c2", "c3", "fc")
EXAMPLE_THETA = (0.3, 0.4, 0.5, 14.0, 0.8, 60.0, 0.002)


class _Loaded:
    """The module the kernels come from now: the native one, or numba's JIT (``ident.kernels``)."""

    def __init__(self) -> None:
        native = load_native(native_path())
        if native is None:
            from . import kernels

            self.source: ModuleType = kernels
        else:
            self.source = native
        self.ahead_of_time = native is not None
        #: Why this process's native build failed (not tried again here, even where no note could be written).
        self.failed: str | None = None


_loaded = _Loaded()


def ahead_of_time() -> bool:
    """True when the kernels run from the native module (no numba in this process)."""
    return _loaded.ahead_of_time


def use_native(path: Path) -> bool:
    """Run the kernels from the native module at ``path`` from now on (False: it does not load)."""
    native = load_native(path)
    if native is not None:
        _loaded.source, _loaded.ahead_of_time = native, True
    return native is not None


def ensure_native() -> str | None:
    """Build the native module where it is missing and run the kernels from it from now on.

    Returns None when the kernels run natively, else why not (numba's JIT then serves them):
    whatever stops the build (no C compiler, a numba without pycc, a read-only folder) must
    never stop a recording.
    """
    if _loaded.ahead_of_time:
        return None
    if _loaded.failed is not None:
        return _loaded.failed
    failed = failure_note()
    if failed.exists():
        return f"{failed.read_text().strip()} (the native build failed; delete {failed} to retry)"
    try:
        path = build()
    except Exception as error:  # any failure leaves the JIT, which always works
        reason = f"{type(error).__name__}: {error}".splitlines()[0].split(". ")[0]  # its first sentence
        _loaded.failed = reason
        with contextlib.suppress(OSError):  # remembered, so that every later run does not retry
            failed.write_text(reason + "\n")
        return reason
    return None if use_native(path) else f"{path.name} was built but does not load"


def warm_jit(names: Sequence[str] = tuple(KERNELS)) -> None:
    """Compile the kernels with numba's JIT into its on-disk cache, for the argument types they are called
    with (those of the signatures exported).

    What the fallback runs, and what the test holding native and JIT equal compares: compiled
    once, in one process, before parallel workers could race to write the same cache file. Each is
    called, not compiled for its signature: numba files an explicit signature's code under that
    signature, and a call looks for its arguments' types, so every process compiled it again.
    """
    from . import kernels

    examples = example_calls()
    for name in names:
        getattr(kernels, name)(*examples[name])


def failure_note() -> Path:
    """Where a failed native build of this kernel source says why (it is not retried while there)."""
    return native_path().with_suffix(".failed")


def build_failed() -> bool:
    """True when the native build of this kernel source failed before (so no build is attempted)."""
    return _loaded.failed is not None or failure_note().exists()


def _checked(name: str) -> Callable[..., Any]:
    """The kernel ``name`` of whichever module is loaded, its arguments made exactly what it takes."""
    converters = [ARGUMENT_KINDS[kind][1] for kind in KERNELS[name][0]]

    def call(*args: Any) -> Any:
        if len(args) != len(converters):
            raise TypeError(f"{name} takes {len(converters)} arguments, got {len(args)}")
        return getattr(_loaded.source, name)(
            *(convert(a) for convert, a in zip(converters, args, strict=True))
        )

    call.__name__ = call.__qualname__ = name
    return call


simulate = _checked("simulate")
simulate_with_sensitivities = _checked("simulate_with_sensitivities")
acceleration_partials = _checked("acceleration_partials")
term_matrix = _checked("term_matrix")
hac_meat = _checked("hac_meat")


#: More sub-steps per sample than any decay needs (omega h < 0.1 at 100 Hz up to 10^4 rad/s).
MAX_SUBSTEPS = 10_000


def term_codes(terms: Sequence[str]) -> np.ndarray:
    """Kernel codes of the named terms (KeyError names the unknown one)."""
    return np.array([TERM_TABLE[name].code for name in terms], dtype=np.int64)


def substeps(dt: float, theta: np.ndarray, terms: Sequence[str], amplitude: float) -> int:
    """RK4 sub-steps per sample so that omega*h stays below 0.1 (phase error ~1e-7 per step)."""
    coeff = dict(zip(terms, np.abs(theta), strict=True))
    stiffness = (
        coeff.get("c1", 0.0)
        + coeff.get("s1", 0.0)
        + 3 * (coeff.get("c3", 0.0) + coeff.get("s3", 0.0)) * amplitude**2
        + 2 * (coeff.get("c2", 0.0) + coeff.get("s2", 0.0)) * amplitude
    )
    rate_scale = math.sqrt(max(stiffness, 1e-12)) + coeff.get("b1", 0.0)
    wanted = 2.0 * rate_scale * dt / 0.1
    # a start no decay has (inf, NaN, absurd stiffness) asks for more steps than a kernel takes: it is
    # then refused by the kernel at once (``kernels.MAX_STEPS``), never integrated for minutes
    return MAX_SUBSTEPS if not wanted < MAX_SUBSTEPS else max(1, math.ceil(wanted))
