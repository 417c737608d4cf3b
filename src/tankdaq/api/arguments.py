"""The Python API's arguments, checked where they enter: each public function, constructor and method
passes what it was given through these before any work starts.

A notebook user types ``tankdaq.read(None)``, ``identify(df)`` or ``plot(decay=99)``; without a check
the call failed deep inside with a TypeError, an IndexError, or a misleading line (``campaign(folder,
hulls="swath")`` iterated the string: "unknown hull 's'"). Each checker returns the value normalised
(a ``Path``, a list, a float) or raises one ``InputError`` that names the argument, says what it takes
and quotes what was given, in one line. What is forgiving on purpose: a ``Path`` where a path is taken,
one string where a list is (one hull), any real number type (numpy's included), and an ``int`` year or a
``date`` for a time.
"""

from __future__ import annotations

import datetime
import math
import numbers
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

from ..config.rules import shown
from ..errors import InputError

T = TypeVar("T")

#: What a DataFrame or an array given where a file is taken should become.
_TABLE_HINT = "save a DataFrame with df.to_csv('decay.csv', index=False) and give the file"


def given(value: object) -> str:
    """A value as a refusing line quotes it: its type for tables and arrays (their repr is many lines),
    else its repr cut short; always one line."""
    kind = type(value)
    if kind.__name__ in ("DataFrame", "Series"):
        return f"a {kind.__name__}"
    if kind.__name__ == "ndarray":
        return f"an array of shape {getattr(value, 'shape', '?')}"
    return shown(value).replace("\n", " ")


def refuse(name: str, takes: str, value: object, hint: str = "") -> InputError:
    """The one line: the argument, what it takes, what it was given (and what to do, when known)."""
    return InputError(f"{name}: give {takes}, not {given(value)}" + (f" ({hint})" if hint else ""))


def _is_table(value: object) -> bool:
    return type(value).__name__ in ("DataFrame", "Series", "ndarray")


def path(value: object, name: str, takes: str = "a path (str or pathlib.Path)") -> Path:
    """A file or folder path: a non-empty str or any ``os.PathLike``."""
    if isinstance(value, str | os.PathLike) and not isinstance(value, bytes):
        text = os.fspath(value)
        if isinstance(text, str) and text and "\0" not in text:
            return Path(text)
    raise refuse(name, takes, value, _TABLE_HINT if _is_table(value) else "")


def optional_path(
    value: object, name: str, takes: str = "a path (str or pathlib.Path) or None"
) -> Path | None:
    return None if value is None else path(value, name, takes)


def paths(value: object, name: str, takes: str = "a path or a list of paths") -> list[Path]:
    """One path or several (a list or tuple of them, at least one)."""
    if isinstance(value, str | os.PathLike):
        return [path(value, name, takes)]
    items = several(value, name, takes)
    return [path(item, name, takes) for item in items]


def several(value: object, name: str, takes: str) -> list[Any]:
    """The items of a list or tuple, at least one (a set has no order; a dict, a table or an array are
    not a list of arguments)."""
    if isinstance(value, list | tuple) and value:
        return list(value)
    raise refuse(name, takes, value, _TABLE_HINT if _is_table(value) else "")


def text(value: object, name: str, takes: str = "a string", choices: Sequence[str] = ()) -> str:
    """A non-empty string; one of ``choices`` when they are given (the line then lists them)."""
    if isinstance(value, str) and value.strip() and (not choices or value in choices):
        return value
    raise refuse(name, f"one of {', '.join(map(repr, choices))}" if choices else takes, value)


def optional_text(
    value: object, name: str, takes: str = "a string or None", choices: Sequence[str] = ()
) -> str | None:
    """``text``, or None."""
    if value is None:
        return None
    if isinstance(value, str) and value.strip() and (not choices or value in choices):
        return value
    raise refuse(name, f"None or one of {', '.join(map(repr, choices))}" if choices else takes, value)


def texts(value: object, name: str, takes: str = "a string or a list of strings") -> list[str]:
    """One string or several (a list or tuple, at least one): a single string is one item, never its
    characters."""
    if isinstance(value, str):
        return [text(value, name, takes)]
    return [text(item, name, takes) for item in several(value, name, takes)]


def names(value: object, name: str, takes: str = "a name, a path, or a list of them") -> list[str]:
    """Names or paths (hulls by name or .toml): one or several, as strings; none (an empty list) is
    allowed."""
    if isinstance(value, list | tuple) and not value:
        return []
    if isinstance(value, str | os.PathLike):
        value = [value]
    return [str(path(item, name, takes)) for item in several(value, name, takes)]


def model(value: object, name: str = "model") -> str:
    """A model as ``physics.models.resolve_model`` reads it: ``"auto"``, terms (``"b1,b2,c1,c3"``), an
    alias, or a list of term names (joined)."""
    if isinstance(value, str) and value.strip():
        return value
    if isinstance(value, list | tuple) and value and all(isinstance(v, str) and v.strip() for v in value):
        return ",".join(value)
    raise refuse(name, "'auto', terms as 'b1,b2,c1,c3' (a string or a list of them) or an alias", value)


def _within(value: object, low: float, high: float) -> bool:
    """A finite real number (not a bool) from ``low`` to ``high``."""
    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        return False
    return math.isfinite(float(value)) and low <= float(value) <= high


def _number_takes(low: float, high: float, unit: str) -> str:
    bounds = [
        f"at least {low:g}" if math.isfinite(low) else "",
        f"at most {high:g}" if math.isfinite(high) else "",
    ]
    within = " and ".join(bound for bound in bounds if bound)
    return f"a finite number{' of ' + unit if unit else ''}" + (f", {within}" if within else "")


def number(value: object, name: str, low: float = -math.inf, high: float = math.inf, unit: str = "") -> float:
    """A finite real number (int, float, numpy's) from ``low`` to ``high``; not a bool, not a string."""
    if _within(value, low, high):
        return float(value)  # type: ignore[arg-type]  # a Real
    raise refuse(name, _number_takes(low, high, unit), value)


def optional_number(
    value: object, name: str, low: float = -math.inf, high: float = math.inf, unit: str = ""
) -> float | None:
    """``number``, or None."""
    if value is None or _within(value, low, high):
        return None if value is None else float(value)  # type: ignore[arg-type]  # a Real
    raise refuse(name, _number_takes(low, high, unit) + ", or None", value)


def whole(value: object, name: str, low: int, high: int) -> int:
    """An integer (int or numpy's) from ``low`` to ``high``; ``1.5``, ``True`` and ``"3"`` are refused,
    not rounded."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) and low <= int(value) <= high:
        return int(value)
    raise refuse(name, f"a whole number from {low} to {high}", value)


def flag(value: object, name: str) -> bool:
    """True or False (numpy's bool too); ``1`` or ``"yes"`` are refused, not guessed."""
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return bool(value)
    raise refuse(name, "True or False", value)


def draft(value: object, name: str = "draft") -> str:
    """A draft as the drafts are written: a factor of the design draft (``1.1``) or ``"0.9T"``, ``"T"``,
    ``"1.1T"``; returned as text for ``config.validation.draft_factor`` (which checks its range)."""
    if isinstance(value, str) and value.strip():
        return value
    if isinstance(value, numbers.Real) and not isinstance(value, bool) and 0 < float(value) < math.inf:
        from ..config.hulls import format_draft

        return format_draft(float(value))
    raise refuse(name, "a factor of the design draft above 0 (1.1) or text as '0.9T', 'T', '1.1T'", value)


def instance(value: object, name: str, kind: type[T], takes: str) -> T:
    """An object of ``kind``."""
    if isinstance(value, kind):
        return value
    raise refuse(name, takes, value)


def optional_instance(value: object, name: str, kind: type[T], takes: str) -> T | None:
    return None if value is None else instance(value, name, kind, takes)


def callback(value: object, name: str, takes: str = "a function or None") -> Callable[..., Any] | None:
    """A callable, or None."""
    if value is None or callable(value):
        return value
    raise refuse(name, takes, value)


def progress(value: object, name: str = "progress") -> Any:
    """None or an object with ``line(text)`` and ``task(description, total)`` (``api.progress.Progress``)."""
    if value is None or (callable(getattr(value, "line", None)) and callable(getattr(value, "task", None))):
        return value
    raise refuse(name, "None or an object with line(text) and task(description, total)", value)


def when(value: object, name: str) -> str | None:
    """A time for a filter: a string as the query language reads it, a ``date`` or ``datetime`` (as ISO
    text), or an int year (``2026``); None: no filter."""
    if value is None:
        return None
    if isinstance(value, datetime.date):  # a datetime is a date too
        return value.isoformat(sep=" ") if isinstance(value, datetime.datetime) else value.isoformat()
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) and 1 <= int(value) <= 9999:
        return f"{int(value):04d}"
    if isinstance(value, str) and value.strip():
        return value
    raise refuse(
        name, "a date: text as '2026-11-28' or '2026-11', a datetime.date or datetime, or a year", value
    )


def index(value: object, name: str, count: int, what: str) -> int:
    """A position in a list of ``count`` ``what`` (from 0; a negative one counts from the end)."""
    if (
        count
        and isinstance(value, numbers.Integral)
        and not isinstance(value, bool)
        and -count <= int(value) < count
    ):
        return int(value) % count
    takes = (
        f"a whole number from 0 to {count - 1} (this result has {count} {what})"
        if count
        else f"nothing: no {what}"
    )
    raise refuse(name, takes, value)


def run_filters(
    filters: Mapping[str, object], catalogue: object, exports: object
) -> tuple[dict[str, str | None], str | None, bool]:
    """``tankdaq.runs``'s arguments by name: each filter text or None (a draft also a factor, ``since``
    also a date or a year), the catalogue a URL or a path (``Path`` too), ``exports`` True or False."""
    checked: dict[str, str | None] = {}
    for name, value in filters.items():
        if name == "since":
            checked[name] = when(value, name)
        elif name == "draft" and value is not None:
            checked[name] = draft(value, name)
        else:
            checked[name] = optional_text(value, name, "text or None")
    takes = "a catalogue's URL or path (str or pathlib.Path), or None"
    url = catalogue if isinstance(catalogue, str) else optional_path(catalogue, "catalogue", takes)
    return checked, None if url is None else str(url), flag(exports, "exports")
