"""One rule per command-line parameter, in one place, shared by every command and by the library.

Each validator takes a value as the user gave it and returns it (normalised) or
raises ``InputError`` with a message that says what to give instead. They run
before a device is opened or any work starts, so a bad flag costs nothing: no
port opened, no simulator started, no file or folder left behind. The CLI wraps
them as typer parameter callbacks (``cli/app.py``).

Path checks try the operation instead of asking ``os.access``: tankdaq often
runs as root in the lab (where ``access`` says yes to everything) and on
read-only or pseudo file systems (``/proc``) only an attempt tells the truth.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import InputError
from ..physics.friction_scaling import checked_temperature_c
from ..physics.models import resolve_model
from ..physics.terms import TERM_TABLE, TERMS
from ..xsens.constants import BAUD_CODES
from .rules import MAX_RELEASE_ANGLE_DEG

if TYPE_CHECKING:
    from .hulls import Hull

#: The MTi's output clock: every output rate is an integer divisor of it (LLCP, SetOutputConfiguration).
MTI_BASE_RATE_HZ = 400

#: Every output rate an MTi accepts: the whole divisors of its clock, shown in --rate's help and errors.
OUTPUT_RATES_HZ: tuple[int, ...] = tuple(
    rate for rate in range(1, MTI_BASE_RATE_HZ + 1) if MTI_BASE_RATE_HZ % rate == 0
)

#: The accepted rates as people read them, "1, 2, 4, ... 400".
OUTPUT_RATES_TEXT = ", ".join(map(str, OUTPUT_RATES_HZ))

#: Serial line rates an MTi accepts (the SetBaudrate codes).
STANDARD_BAUDS: tuple[int, ...] = tuple(sorted(set(BAUD_CODES.values())))


#: Bootstrap replicas beyond this add nothing to a 95 % interval and take hours.
MAX_BOOTSTRAP_REPLICAS = 10_000


def output_rate_hz(value: float, option: str = "--rate") -> float:
    """An MTi output rate: a whole divisor of 400 Hz (``OUTPUT_RATES_HZ``)."""
    if not (math.isfinite(value) and value in OUTPUT_RATES_HZ):
        raise InputError(
            f"{option} {value:g} Hz is not an MTi output rate; "
            f"use a whole divisor of {MTI_BASE_RATE_HZ} Hz: {OUTPUT_RATES_TEXT}"
        )
    return float(value)


def release_angle_deg(value: float, option: str = "--angle") -> float:
    """A nominal release angle: positive degrees up to 45 (the side is found from the data)."""
    if not (math.isfinite(value) and 0 < value <= MAX_RELEASE_ANGLE_DEG):
        raise InputError(
            f"{option} {value:g} is not a release angle; give a positive number of degrees up to "
            f"{MAX_RELEASE_ANGLE_DEG:g}"
        )
    return float(value)


#: The axes a decay test tilts (``samples.AXIS_FIELDS``'s keys).
DECAY_AXES = ("roll", "pitch")


def decay_axis(value: str, option: str = "--axis") -> str:
    """A decay axis: roll or pitch."""
    if value not in DECAY_AXES:
        raise InputError(f"{option} {value!r} not understood: use roll or pitch")
    return value


#: The units a decay file's columns may be given in (``store.csv_units`` holds their factors).
ANGLE_UNIT_WORDS, TIME_UNIT_WORDS = "deg or rad", "s, ms or tick (0.1 ms)"


def angle_unit(value: str, option: str = "--angle-unit") -> str:
    """The unit of a file's angle and rate: deg or rad."""
    if value not in ("deg", "rad"):
        raise InputError(f"{option} {value!r} not understood: use {ANGLE_UNIT_WORDS}")
    return value


def time_unit(value: str, option: str = "--time-unit") -> str:
    """The unit of a file's time: s, ms or tick (an Xsens SampleTimeFine, 0.1 ms)."""
    if value not in ("s", "ms", "tick"):
        raise InputError(f"{option} {value!r} not understood: use {TIME_UNIT_WORDS}")
    return value


def draft_factor(text: str) -> float:
    """A draft as people write it: ``0.9T``, ``T``, ``1.1T`` -> factor of the design draft."""
    from .hulls import parse_draft

    return parse_draft(text)


def known_hull(spec: str) -> Hull:
    """A hull by name (the user's hull folder, then the shipped ones) or by .toml path."""
    from .hulls import load_hull

    return load_hull(spec)


def hull_draft(hull: Hull, draft: float, axis: str | None = None) -> float:
    """A draft the hull is described at on ``axis`` (every axis when None): within the drafts of its
    ``[simulation]`` part when it has one there; a hull without simulated drafts is described at its
    design draft only, and any draft ``draft_factor`` accepts is taken (scaled wall-sided)."""
    for name in [axis] if axis else sorted(hull.simulation):
        if name not in hull.simulation:
            continue
        try:
            hull.simulation[name].coefficients(draft)
        except InputError as exc:
            raise InputError(f"hull {hull.name} ({name}): {exc}; give a draft in that range") from None
    return draft


def baud_rate(value: int | None, option: str = "--baud") -> int | None:
    """A standard MTi baud rate, or None (the command picks one)."""
    if value is not None and value not in STANDARD_BAUDS:
        raise InputError(
            f"{option} {value} is not an MTi baud rate; use one of {', '.join(map(str, STANDARD_BAUDS))}"
        )
    return value


def baud_carries_rate(baud: int | None, rate_hz: float, option: str = "--baud") -> int | None:
    """A line rate that carries the decay outputs at ``rate_hz`` (None: the recorder picks one)."""
    from ..xsens.control import decay_bits_per_second, line_refusal

    refusal = None if baud is None else line_refusal(decay_bits_per_second(rate_hz), rate_hz, baud)
    if refusal is not None:
        raise InputError(f"{option} {baud}: {refusal}")
    return baud


def angle_accuracy_deg(value: float | None, option: str = "--angle-accuracy") -> float | None:
    """A device's roll/pitch accuracy for the uncertainty budget (deg, RMS): above 0, at most 10."""
    if value is not None and not (math.isfinite(value) and 0 < value <= 10):
        raise InputError(
            f"{option} {value:g}: give the device's roll/pitch accuracy in degrees RMS, above 0 and at "
            "most 10 (the MTi-G-710 datasheet's dynamic figure is 0.3)"
        )
    return value


def bootstrap_replicas(value: int, option: str = "--bootstrap") -> int:
    """0 (no bootstrap) up to MAX_BOOTSTRAP_REPLICAS replicas."""
    if not 0 <= value <= MAX_BOOTSTRAP_REPLICAS:
        raise InputError(
            f"{option} {value}: give 0 (no bootstrap) up to {MAX_BOOTSTRAP_REPLICAS} replicas "
            "(1000 is plenty for a 95 % interval)"
        )
    return value


def water_temperature_c(value: float, option: str = "--water-temperature") -> float:
    """A water temperature (degC) ITTC's water properties hold at: 0 to 40."""
    return checked_temperature_c(value, option)


def percent(value: float, option: str, low: float = 0.0, high: float = 100.0) -> float:
    """A percentage strictly between ``low`` and ``high`` (given and checked in %, not as a fraction)."""
    if not (math.isfinite(value) and low < value < high):
        raise InputError(f"{option} {value:g} %: give a percentage between {low:g} and {high:g}, e.g. 10")
    return float(value)


def equation_model(spec: str | Sequence[str], use: str, instead: str) -> tuple[str, ...]:
    """A model of decay-equation terms only (b1 ... s3), for the uses that cannot take friction (``fc``)
    or coupling (``ku``): ``use`` names who refuses, ``instead`` says what to do."""
    terms = resolve_model(spec)
    outside = [term for term in terms if term not in TERMS]
    if outside:
        raise InputError(f"{use} only {' '.join(TERMS)}, not {', '.join(outside)}; {instead}")
    return terms


#: Kinds of term the live identifier cannot fit, and why: it is given the angle and rate alone.
LIVE_REFUSED_KINDS: dict[str, str] = {
    "exogenous": "needs a measured input u(t), and the live identifier is given the angle and rate only",
}


def live_model(spec: str | Sequence[str], option: str = "--model") -> tuple[str, ...]:
    """A model the live identifier, view and recording all carry: every term of the table but those that
    need an input the live pipeline does not have (``ku``)."""
    terms = resolve_model(spec)
    for term in terms:
        why = LIVE_REFUSED_KINDS.get(TERM_TABLE[term].kind)
        if why is not None:
            raise InputError(
                f"{option}: {term} {why}; record without it, then fit it offline with tankdaq diagnose "
                "or tankdaq identify"
            )
    return terms


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity, as a container or taskset sets it): the
    most worker processes that can run at once (more only wait for a core, each with its memory)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


#: Where a campaign's work runs: ``local`` (a process pool) or ``dask`` (a cluster; needs a scheduler).
EXECUTORS = ("local", "dask")


def campaign_executor(
    executor: str, scheduler: str | None, option: str = "--executor", scheduler_option: str = "--scheduler"
) -> str:
    """Where a campaign runs: ``local``, or ``dask`` with a scheduler address (and a scheduler only then;
    whether it answers is ``campaign.executors.check_scheduler``'s)."""
    if executor not in EXECUTORS:
        raise InputError(f"{option} {executor!r} not understood: use local or dask")
    if (executor == "dask") != (scheduler is not None):
        raise InputError(
            f"{option} dask needs {scheduler_option} ADDRESS, and {scheduler_option} needs {option} dask"
        )
    return executor


def _cannot_write_in(folder: Path) -> str | None:
    """Why a file cannot be created in ``folder`` (None: it can). Tries it: the only check that holds
    for root and for read-only or pseudo file systems. The probe file is removed at once."""
    try:
        fd, name = tempfile.mkstemp(prefix=".tankdaq-probe-", dir=folder)
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    os.unlink(name)
    return None


def output_dir(path: Path, option: str = "--out") -> Path:
    """A folder files can be written into, or one that can be created: nothing is left behind by the
    check (the command creates the folder when it writes), so a refused command leaves no trace."""
    path = Path(path)
    existing = next((p for p in (path, *path.parents) if p.exists()), Path.cwd())
    if not existing.is_dir():
        raise InputError(f"{option} {path}: {existing} is a file, not a folder; give a folder")
    why = _cannot_write_in(existing)
    if why is not None:
        action = "write files there" if existing == path else f"create it in {existing}"
        raise InputError(f"{option} {path}: cannot {action} ({why}); choose a writable folder")
    return path


def output_file(path: Path, option: str = "--out") -> Path:
    """A file path that can be written: not a folder, in an existing writable folder."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{option} {path} is a folder; give a file name")
    folder = path.parent
    if not folder.is_dir():
        state = "is not a folder" if folder.exists() else "does not exist"
        raise InputError(f"{option} {path}: the folder {folder} {state}; create it or choose another")
    why = _cannot_write_in(folder)
    if why is not None:
        raise InputError(f"{option} {path}: cannot write in {folder} ({why}); choose a writable folder")
    return path


#: What tankdaq does with a file of the name it would write: the rule ``--help`` says and errors repeat.
NEVER_OVERWRITES = "tankdaq never writes over a file; move it, or write into another folder"


def refuse_existing(paths: Iterable[Path]) -> None:
    """Every path is free (nothing there, not even a dangling symbolic link), or one line naming the
    first that is not: tankdaq writes new files only (``store.safe_write``)."""
    for path in paths:
        if os.path.lexists(path):
            kind = (
                "a symbolic link, not followed"
                if path.is_symlink()
                else "a folder"
                if path.is_dir()
                else "a file"
            )
            raise InputError(f"{path} exists ({kind}): {NEVER_OVERWRITES}")


def report_dir(path: Path, names: Sequence[str], option: str = "--report") -> Path:
    """A report's folder (``output_dir``) holding none of the report's ``names``: refused before any work."""
    path = output_dir(path, option)
    refuse_existing(path / name for name in names)
    return path


def new_file(path: Path, option: str = "--out") -> Path:
    """A file to write (``output_file``) where nothing is yet: tankdaq never writes over a file."""
    path = output_file(path, option)
    refuse_existing([path])
    return path


def input_file(path: Path, what: str = "file", error: type[InputError] = InputError) -> Path:
    """An existing, readable regular file (a folder or a missing path says which it is).

    ``error`` is the InputError subclass the caller's domain raises (BadRecordingInput for readers).
    """
    path = Path(path)
    if path.is_dir():
        raise error(f"{path} is a folder, not a {what}; give the {what} itself")
    if not path.exists():
        raise error(f"{path}: no such {what}")
    if not path.is_file():
        raise error(f"{path} is not a regular file; give the {what} itself")
    try:
        with path.open("rb"):
            pass
    except OSError as exc:
        raise error(f"cannot read {path}: {exc.strerror}") from None
    return path


__all__ = [
    "LIVE_REFUSED_KINDS",
    "MAX_BOOTSTRAP_REPLICAS",
    "MAX_RELEASE_ANGLE_DEG",
    "MTI_BASE_RATE_HZ",
    "OUTPUT_RATES_HZ",
    "OUTPUT_RATES_TEXT",
    "STANDARD_BAUDS",
    "baud_rate",
    "bootstrap_replicas",
    "draft_factor",
    "equation_model",
    "hull_draft",
    "input_file",
    "known_hull",
    "live_model",
    "new_file",
    "output_dir",
    "output_file",
    "output_rate_hz",
    "percent",
    "refuse_existing",
    "release_angle_deg",
    "report_dir",
    "usable_cores",
]
