"""What a hull or plan file must be, checked where it is read, and the names that become file names.

A TOML file is untrusted input like any flag: it is read within a size bound, its nesting is bounded,
every number in it is finite and of a sane size, a key that is not known is refused with the nearest
known one, and each value is checked against its range, all before a device or an output file opens,
with one line that names the file, the key and what to write instead (``ConfigError``, exit 2).

A hull name becomes part of every recording's file name and of report files: ``safe_name`` is the one
rule for such names, and ``path_in`` (a file name joined to its folder) refuses a name that would leave
the folder, the second line of defence wherever a path is made from one.
"""

from __future__ import annotations

import codecs
import difflib
import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import ConfigError, InputError

#: A hull or plan file is a few kB; beyond this it is not one (and is not read into memory).
MAX_TOML_BYTES = 1 << 20
#: Hull files nest four levels ([simulation.roll.drafts."T"]); deeper is not a hull or plan file.
MAX_TOML_DEPTH = 8
#: No number in a hull or plan file is larger than this (a displacement in kg of the largest ship is 1e9).
MAX_NUMBER = 1e15
#: A name that becomes part of a file name: at most this long (recording names add about 40 characters).
MAX_NAME_CHARS = 64
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")
#: The rule, as the refusing line states it.
NAME_RULE = (
    f"letters, digits, '-' and '_' (starting with a letter or digit), at most {MAX_NAME_CHARS} characters"
)
#: A release angle beyond this is not a decay test (and beyond the models' validity).
MAX_RELEASE_ANGLE_DEG = 45.0


def shown(value: object, limit: int = 40) -> str:
    """A value as a refusing line quotes it: its repr, cut to ``limit`` characters (one line always)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def safe_name(name: object, what: str) -> str:
    """``name`` when it can be part of a file name (``NAME_RULE``); else one line saying the rule."""
    if isinstance(name, str) and len(name) <= MAX_NAME_CHARS and _NAME.fullmatch(name):
        return name
    raise InputError(f"{what} {shown(name)} cannot be part of a file name: use {NAME_RULE}")


def path_in(folder: Path, name: str) -> Path:
    """``folder / name`` for a plain file name; a name that would leave ``folder`` (a separator, ``..``,
    an absolute path, NUL) is refused: the second line of defence behind ``safe_name``."""
    if name in ("", ".", "..") or any(bad in name for bad in ("/", "\\", "\0")):
        raise InputError(
            f"{shown(name)} is not a file name inside {folder}: refused (it would leave the folder)"
        )
    return folder / name


def read_toml(path: Path) -> dict[str, Any]:
    """A TOML file read within bounds (size, nesting), every number finite and at most ``MAX_NUMBER``."""
    try:
        size = path.stat().st_size
        if size > MAX_TOML_BYTES:
            raise ConfigError(f"{path}: {size} bytes is not a hull or plan file (at most {MAX_TOML_BYTES})")
        with path.open("rb") as fh:
            data = toml_text(fh.read(MAX_TOML_BYTES + 1), path)
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}); save it as UTF-8") from None
    except (tomllib.TOMLDecodeError, ValueError) as exc:  # ValueError: an integer of over 4300 digits
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply (at most {MAX_TOML_DEPTH} levels)") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read it: {exc.strerror or exc}") from None
    _check_tree(data, path)
    return data


def toml_text(raw: bytes, path: Path) -> dict[str, Any]:
    """The TOML in ``raw``: a UTF-8 byte-order mark (Windows Notepad's "UTF-8 with BOM") is dropped, as
    TOML itself refuses it at line 1, column 1; a UTF-16 file is named, not reported as a bad byte."""
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise ConfigError(f"{path}: saved as UTF-16 (Unicode); save it as UTF-8")
    return tomllib.loads(raw.removeprefix(codecs.BOM_UTF8).decode("utf-8"))


def _check_tree(data: dict[str, Any], path: Path) -> None:
    """Every value of the tree: nested at most ``MAX_TOML_DEPTH`` deep, numbers finite and sane."""
    stack: list[tuple[str, Any, int]] = [("", data, 0)]
    while stack:
        where, value, depth = stack.pop()
        if depth > MAX_TOML_DEPTH:
            raise ConfigError(
                f"{path}: {where or 'the file'} is nested too deeply (at most {MAX_TOML_DEPTH} levels)"
            )
        if isinstance(value, dict):
            stack.extend((f"{where}.{k}" if where else str(k), v, depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((f"{where}[{i}]", v, depth + 1) for i, v in enumerate(value))
        elif isinstance(value, int | float) and not isinstance(value, bool) and not _sane(value):
            size = "not finite" if isinstance(value, float) and not math.isfinite(value) else "too large"
            raise ConfigError(
                f"{path}: {where} = {shown(value, 24)} is {size}; numbers here are finite and at most "
                f"{MAX_NUMBER:g} in size"
            )


def _sane(value: float) -> bool:
    """Finite and at most ``MAX_NUMBER`` (an int of any size compares exactly, never overflows)."""
    return (
        abs(value) <= MAX_NUMBER
        if isinstance(value, int)
        else math.isfinite(value) and abs(value) <= MAX_NUMBER
    )


def refuse_unknown(table: Mapping[str, Any], known: Iterable[str], where: str) -> None:
    """One line for the first key not in ``known``, with the nearest known one suggested."""
    names = sorted(known)
    for key in table:
        if key not in names:
            near = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
            hint = f"did you mean {near[0]!r}?" if near else f"known: {', '.join(names)}"
            raise ConfigError(f"{where}: unknown key {shown(key)}; {hint}")


def table(data: Mapping[str, Any], key: str, where: str) -> dict[str, Any]:
    """The sub-table ``key`` (empty when absent); anything else than a table is refused."""
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: {key} must be a table ([{key}]), not {shown(value)}")
    return value


def text(data: Mapping[str, Any], key: str, where: str, default: str = "") -> str:
    """A string value (``default`` when absent)."""
    value = data.get(key, default)
    if not isinstance(value, str):
        raise ConfigError(f"{where}: {key} must be a string in quotes, not {shown(value)}")
    return value


def number(value: object, where: str, low: float, high: float, low_open: bool = True) -> float:
    """A number (not a string, not true/false) with ``low < value <= high`` (``low <= ...`` unless
    ``low_open``); the line says the range."""
    within = isinstance(value, int | float) and not isinstance(value, bool) and _sane(value)
    if within:
        within = (low < value if low_open else low <= value) and value <= high  # type: ignore[operator]
    if not within:
        above = "above" if low_open else "at least"
        raise ConfigError(
            f"{where} must be a number {above} {low:g} and at most {high:g}, not {shown(value)}"
        )
    return float(value)  # type: ignore[arg-type]


def whole_number(value: object, where: str, low: int, high: int) -> int:
    """An integer from ``low`` to ``high`` (``1.5`` and ``true`` are refused, not rounded)."""
    if not (isinstance(value, int) and not isinstance(value, bool) and low <= value <= high):
        raise ConfigError(f"{where} must be a whole number from {low} to {high}, not {shown(value)}")
    return value


def listed(value: object, where: str, what: str, example: str) -> list[Any]:
    """A non-empty list (a string is refused, not split into its characters)."""
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where} must be a non-empty list of {what}, e.g. {example}; not {shown(value)}")
    return value


def uncertainty_key(key: str) -> str:
    """The key of a value's standard uncertainty: gm_m -> gm_uncertainty_m, displacement_kg ->
    displacement_uncertainty_kg (docs/hulls.md)."""
    name, unit = key.rsplit("_", 1)
    return f"{name}_uncertainty_{unit}"


def uncertainty(spec: dict[str, Any], key: str, values: dict[str, float], where: str) -> float | None:
    """The standard uncertainty of ``key`` the table gives (None: not given): zero or more and below
    the value itself, which it needs beside it."""
    said = uncertainty_key(key)
    if spec.get(said) is None:
        return None
    if key not in values:
        raise ConfigError(f"{where}.{said} is given without {key}: give {key} too, or remove it")
    u = number(spec[said], f"{where}.{said}", 0.0, values[key], low_open=False)
    if u >= values[key]:
        raise ConfigError(
            f"{where}.{said} = {u:g} must be below {key} = {values[key]:g} (a standard uncertainty)"
        )
    return u
