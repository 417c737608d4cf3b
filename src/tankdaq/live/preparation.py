"""The live fit's kernels made ready before a device opens, so no refit pays for them during a decay.

``prepare_kernels`` builds the native module (the first run after install) or compiles numba's kernels
on a made-up decay; ``prepare_identifier`` does it and says so in a line.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import IdentificationError
from ..ident import compiled
from ..ident.user_cache import shown
from .identifier import OnlineIdentifier


def prepare_kernels(terms: str | Sequence[str] = "ittc-quadratic-restoring") -> str | None:
    """Make every kernel a live fit uses ready before a device opens; None, or why not native.

    The native module is built on the first run (``ident.compiled``) and then loads in a
    millisecond. Where it cannot be, numba's JIT compiles (first run) or loads the kernels on a
    made-up decay: the first refit of a decay would otherwise spend 10-40 s compiling (0.6 s
    loading from the cache) wherever it runs.
    """
    reason = compiled.ensure_native()
    if reason is None:
        return None
    t = np.arange(0.0, 12.0, 0.01)
    omega, zeta = 2.0 * np.pi / 2.0, 0.05
    envelope = 0.14 * np.exp(-zeta * omega * t)
    angle = envelope * np.cos(omega * t)
    rate = np.gradient(angle, t)
    identifier = OnlineIdentifier(terms, min_half_cycles=2)
    identifier.update(t[: t.size // 2], angle[: t.size // 2], rate[: t.size // 2])
    identifier.update(t[t.size // 2 :], angle[t.size // 2 :], rate[t.size // 2 :])
    with contextlib.suppress(
        IdentificationError
    ):  # a model this made-up decay does not suit: compiled anyway
        identifier.finish()
    return reason


#: How long compiling the kernels takes on a 2-core PC, quiet to loaded (``bench/bench_live_fit.py``).
FIRST_RUN_S = "10–40"


def first_run_notice() -> str | None:
    """The line a first run says before it builds the kernels (how long, how big, where); None when
    they are ready (or their build failed before: no build is attempted then)."""
    if compiled.ahead_of_time() or compiled.build_failed():
        return None
    return (
        "preparing the identifier (first run after install): building native kernels (once, "
        f"about {FIRST_RUN_S} s, {compiled.NATIVE_SIZE_MB:g} MB) into {shown(compiled.kernel_folder())}"
    )


def prepare_identifier(terms: str | Sequence[str], on_event: Callable[[str], None] | None = None) -> None:
    """``prepare_kernels``, saying so in one line when it means building them (the first run after
    install) and in another when the kernels run on numba's JIT (slower to start) and why."""
    notice = first_run_notice()
    if notice is not None and on_event is not None:
        on_event(notice)
    reason = prepare_kernels(terms)
    if reason is not None and on_event is not None:
        on_event(f"identifier kernels on numba's JIT, slower to start: {reason}")
