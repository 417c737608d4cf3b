"""Xsens MT Manager text exports, every generation, read into a CSV's columns.

MT Manager writes a block of ``//`` lines, then one header line and the samples:

- 4.x: ``// Start Time: ...``, ``// Update Rate: 100.0Hz``, ``// Filter Profile: ...``, ``// Option Flags``
  (may be missing), ``// Firmware Version: ...``; tab-separated, CRLF, PacketCounter zero-padded
  (``03583``), empty fields for outputs not logged;
- 2019.2 and later: ``// General information:`` (MT Manager version), ``// Device information:``
  (DeviceId, ProductCode, Firmware Version), ``// Device settings:`` (Filter Profile, Option Flags),
  ``// Coordinate system: ENU``, and no update rate;
- 2022.2: the same block, ``NaN`` for missing values, tab, comma, semicolon or space as the delimiter
  (a space-separated row marks an empty field by two spaces in a row).

The delimiter is the first of tab, semicolon, comma and space that splits the header into names. The
time comes from SampleTimeFine (10 kHz ticks, unwrapped at the device family's modulus: one day on the
10/100-series, 2**32 on the others, and 2**32 whenever a tick passes one day), else from PacketCounter
(wrapping at 2**16) at the header's update rate, else at ``--rate``; the choice is said in one line. The
header's facts become the run's metadata (``HEADER_FACTS``: device id, product code, firmware, filter
profile, MT Manager version, update rate). A file without the ``//`` block whose header names
SampleTimeFine or PacketCounter (an export with the block cut off) is read the same way.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..xsens.timebase import (
    COUNTER_MODULUS,
    MODULUS_32_BIT,
    MODULUS_ONE_DAY,
    TICKS_PER_SECOND,
    SampleTimeUnwrapper,
    sample_time_modulus,
)
from .csv_import import ColumnData, CsvOptions
from .orientation_columns import euler_index, matrix_index, quaternion_index

#: The delimiters MT Manager writes, in the order tried, and their names.
DELIMITERS = {"\t": "tab", ";": "semicolon", ",": "comma", " ": "space"}
#: A header line's ``//`` key (lower case, spaces removed) -> the run's metadata key.
HEADER_FACTS = {
    "deviceid": "device_id",
    "productcode": "product_code",
    "firmwareversion": "firmware",
    "hardwareversion": "hardware",
    "filterprofile": "filter_profile",
    "optionflags": "option_flags",
    "mtmanagerversion": "mt_manager_version",
    "xdaversion": "xda_version",
    "coordinatesystem": "coordinate_system",
    "starttime": "start_time",
    "updaterate": "update_rate",
    "samplerate": "update_rate",
    "outputrate": "update_rate",
}
#: The columns time is taken from, as MT Manager names them (lower case).
SAMPLE_TIME, COUNTER = "sampletimefine", "packetcounter"
_RATE = re.compile(r"^\s*([0-9]+(?:[.,][0-9]*)?)\s*(?:hz)?\s*$", re.IGNORECASE)
_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+(?:[eE][+-]?\d+)?$")


def is_mt_manager(path: Path) -> bool:
    """The file starts with MT Manager's ``//`` block, or its header names SampleTimeFine or
    PacketCounter (an export with the block cut off)."""
    with path.open("rb") as fh:
        head = fh.read(4096).lstrip(b"\xef\xbb\xbf").lstrip()
    if head.startswith(b"//"):
        return True
    first = head.split(b"\n", 1)[0].lower()
    return any(name.encode() in re.split(rb"[\t;, \r]+", first) for name in (SAMPLE_TIME, COUNTER))


def read_mt_manager(path: Path, options: CsvOptions) -> ColumnData:
    """The numeric columns of an MT Manager text export, a ``time_s`` column (s) made from the device's
    clock unless another time column is asked for, its header's facts as metadata and its lines."""
    lines = _lines(path)
    block = [line for line in lines if line.startswith("//")]
    rows = [
        (number, line) for number, line in enumerate(lines, 1) if line.strip() and not line.startswith("//")
    ]
    if len(rows) < 2:
        raise InputError(f"{path}: an MT Manager export with no data rows after its header line")
    facts = header_facts(block)
    separator = _separator(path, rows[0][1])
    names = [name.strip() for name in rows[0][1].split(separator)]
    split = [(number, line.split(separator)) for number, line in rows[1:]]
    columns, text, empty, decimal_comma = _columns(path, names, split, separator)
    kind = _generation(facts)
    commas = ", decimal commas" if decimal_comma else ""
    said = [f"{path.name}: read as an MT Manager {kind}, {DELIMITERS[separator]}-separated{commas}"]
    if empty:
        said.append(f"{path.name}: empty columns not read: {', '.join(empty)}")
    columns = _oriented_rows(path, columns, said)
    stated = {name: "deg" for name in columns if euler_index(name) is not None}
    asked, derived = options.time_col, options.time_col == "time_s" and "time_s" not in columns
    if derived or (asked in columns and asked.lower() == COUNTER):  # a counter asked for: in s, at a rate
        columns[asked], line = device_time(path, columns, facts, options.sample_rate_hz, not derived)
        stated[asked] = "s"
        said.append(f"{path.name}: {line}")
    elif asked in columns and asked.lower() == SAMPLE_TIME and np.isfinite(columns[asked]).all():
        columns[asked] = _unwrapped(path, asked, columns[asked], facts)[0].astype(float)  # in ticks
    header: dict[str, object] = {key: value for key, value in facts.items() if key != "update_rate"}
    rate = _header_rate(facts)
    if rate is not None:
        header["update_rate_hz"] = rate
    header["source_format"] = f"MT Manager {kind}"
    return ColumnData(columns, dict.fromkeys(text, "holds text"), header, stated, said)


def file_facts(path: Path) -> dict[str, str]:
    """The header's facts of an MT Manager export (its leading ``//`` lines only); empty for any other
    file, or one that cannot be read."""
    block: list[str] = []
    try:
        with path.open(encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if not line.lstrip("\ufeff").startswith("//"):
                    break
                block.append(line.lstrip("\ufeff").rstrip("\r\n"))
    except OSError:
        return {}
    return header_facts(block)


def header_facts(block: list[str]) -> dict[str, str]:
    """The ``// Key: value`` lines of MT Manager's block as metadata (``HEADER_FACTS``); section titles
    (``// Device information:``) and keys tankdaq does not know are left out."""
    facts: dict[str, str] = {}
    for line in block:
        key, colon, value = line.lstrip("/").partition(":")
        name = HEADER_FACTS.get(re.sub(r"[\s_]", "", key).lower())
        if colon and name is not None and value.strip():
            facts[name] = value.strip()
    return facts


def _lines(path: Path) -> list[str]:
    """The file's lines (CRLF, LF or CR), UTF-8 or, where its bytes are not, Windows-1252."""
    data = path.read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("cp1252", "replace")
    return text.splitlines()


def _separator(path: Path, header: str) -> str:
    for separator in DELIMITERS:
        if len([name for name in header.split(separator) if name.strip()]) >= 2:
            return separator
    raise InputError(
        f"{path}: the MT Manager header line {header[:60]!r} is not split by a tab, semicolon, comma or "
        "space: export it again from MT Manager"
    )


def _columns(
    path: Path, names: list[str], numbered: list[tuple[int, list[str]]], separator: str
) -> tuple[dict[str, np.ndarray], list[str], list[str], bool]:
    """(numeric columns, text columns, empty columns, decimal commas) of the rows; an empty field or
    ``NaN`` is NaN, a row with more fields than the header is refused in one line naming it."""
    width = len(names)
    while width and not names[width - 1]:  # a delimiter ending the header line
        width -= 1
    for number, row in numbered:
        if len(row) > width and any(cell.strip() for cell in row[width:]):
            raise InputError(
                f"{path}: line {number} has {len(row)} fields, the header {width} "
                f"({DELIMITERS[separator]}-separated): a row cut or joined; export it again"
            )
    rows = [row for _, row in numbered]
    padded = [row[:width] + [""] * (width - len(row)) for row in rows]
    decimal_comma = separator != "," and any(
        _DECIMAL_COMMA.match(cell.strip()) for row in padded[:200] for cell in row
    )
    columns: dict[str, np.ndarray] = {}
    text: list[str] = []
    empty: list[str] = []
    for name, cells in zip(names[:width], zip(*padded, strict=True), strict=True):
        values = _numbers(cells, decimal_comma)
        if values is None:
            text.append(name)
        elif np.isnan(values).all():
            empty.append(name)
        else:
            columns[name] = values
    return columns, text, empty, decimal_comma


def _numbers(cells: tuple[str, ...], decimal_comma: bool) -> np.ndarray | None:
    """A column's cells as numbers (an empty cell or ``NaN``: NaN), None for a column of text; a column
    with no empty cell is read in one numpy call."""
    if decimal_comma:
        cells = tuple(cell.replace(",", ".") for cell in cells)
    else:
        try:
            return np.asarray(cells, dtype=float)
        except ValueError:  # an empty cell, or text
            pass
    try:
        return np.asarray([cell.strip() or "nan" for cell in cells], dtype=float)
    except ValueError:
        return None


def _oriented_rows(path: Path, columns: dict[str, np.ndarray], said: list[str]) -> dict[str, np.ndarray]:
    """The rows from the first to the last with every orientation value (before the filter has a
    solution, or after the logging stopped, MT Manager leaves them empty), the rows left out said."""
    oriented = [
        values
        for name, values in columns.items()
        if any(index(name) is not None for index in (euler_index, quaternion_index, matrix_index))
    ]
    if not oriented:
        return columns
    whole = np.flatnonzero(np.isfinite(np.column_stack(oriented)).all(axis=1))
    rows = len(oriented[0])
    if whole.size == 0 or (whole[0] == 0 and whole[-1] == rows - 1):
        return columns
    first, last = int(whole[0]), int(whole[-1])
    left = f"{first} at the start, {rows - 1 - last} at the end"
    said.append(f"{path.name}: rows without an orientation not read: {left}")
    return {name: values[first : last + 1] for name, values in columns.items()}


def _generation(facts: dict[str, str]) -> str:
    """Which MT Manager wrote the export, as its header shows it."""
    version = facts.get("mt_manager_version")
    if version:
        return f"{version.split()[0]} text export"
    if "start_time" in facts or "update_rate" in facts:
        return "4.x text export"
    return "text export (no // header)" if not facts else "2019.2+ text export"


def _header_rate(facts: dict[str, str]) -> float | None:
    found = _RATE.match(facts.get("update_rate", ""))
    rate = float(found.group(1).replace(",", ".")) if found else math.nan
    return rate if math.isfinite(rate) and rate > 0 else None


def _named(columns: dict[str, np.ndarray], lower: str) -> str | None:
    return next((name for name in columns if name.lower() == lower), None)


def device_time(
    path: Path, columns: dict[str, np.ndarray], facts: dict[str, str], rate_hz: float | None, counter: bool
) -> tuple[np.ndarray, str]:
    """Each row's time (s) and the one line saying where it came from: SampleTimeFine (unless
    ``counter``: PacketCounter asked for), else PacketCounter at the header's update rate or
    ``rate_hz``, else the row number at ``rate_hz``."""
    ticks = None if counter else _named(columns, SAMPLE_TIME)
    if ticks is not None and np.isfinite(columns[ticks]).all():
        unwrapped, modulus, wraps = _unwrapped(path, ticks, columns[ticks], facts)
        unused = f"; --rate {rate_hz:g} not used" if rate_hz is not None else ""
        return unwrapped / TICKS_PER_SECOND, (
            f"time from {ticks} (10 kHz ticks, {_wraps(wraps, modulus)}){unused}"
        )
    missing = f"{ticks} has empty cells" if ticks is not None else "no SampleTimeFine values"
    missing = "--time-col PacketCounter" if counter else missing
    header_rate = _header_rate(facts)
    rate, whose = (header_rate, "the header's Update Rate") if header_rate else (rate_hz, "--rate")
    if rate is None:
        raise InputError(
            f"{path}: {missing} and no update rate in its header (MT Manager 2019.2 and later write none): "
            "give the sample rate with --rate HZ (identify, diagnose, report; tankdaq.read's sample_rate_hz)"
        )
    name = _named(columns, COUNTER)
    if name is None or not np.isfinite(columns[name]).all():
        count = np.arange(len(next(iter(columns.values()))), dtype=float)
        return count / rate, f"time from the row number at {whose} {rate:g} Hz ({missing}, no PacketCounter)"
    raw = columns[name].astype(np.int64)
    steps = np.diff(raw) % COUNTER_MODULUS
    lost = int(np.sum(steps[steps > 0] - 1))
    count = np.concatenate([[0], np.cumsum(steps)]).astype(float)
    wraps = int(np.sum(np.diff(raw) < 0))
    return count / rate, (
        f"time from {name} at {whose} {rate:g} Hz ({missing}; counter wrapped at 2^16 {wraps} "
        f"time{'s' if wraps != 1 else ''}, {lost} packets missing)"
    )


def _unwrapped(path: Path, name: str, raw: np.ndarray, facts: dict[str, str]) -> tuple[np.ndarray, int, int]:
    """SampleTimeFine ticks unwrapped at the device's modulus, with the modulus and the number of wraps;
    a value no tick count can be is one line. The product code's family is taken unless the data say
    otherwise: 2**32 when a tick passes one day, one day when only that makes the clock run forward
    (a product code the family table does not know)."""
    bad = np.flatnonzero((raw < 0) | (raw >= MODULUS_32_BIT) | (raw != np.round(raw)))
    if bad.size:
        raise InputError(
            f"{path}: {name} row {int(bad[0]) + 1} holds {raw[bad[0]]:.10g}, no 10 kHz tick count (a whole "
            "number 0 to 2^32 - 1): a column of something else, or give --time-col"
        )
    ticks = raw.astype(np.int64)
    past_a_day = int(ticks.max()) >= MODULUS_ONE_DAY
    family = MODULUS_32_BIT if past_a_day else sample_time_modulus(facts.get("product_code", ""))
    candidates = (
        [family] if past_a_day else sorted({MODULUS_ONE_DAY, MODULUS_32_BIT}, key=lambda m: m != family)
    )
    for modulus in candidates:  # the family's first; the other only where it alone runs forward
        unwrapped = SampleTimeUnwrapper(modulus).update_many(ticks)
        if (np.diff(unwrapped) > 0).all():
            break
    else:
        modulus = family
        unwrapped = SampleTimeUnwrapper(modulus).update_many(ticks)
    wraps = int(np.sum(np.diff(ticks) < -(modulus // 2)))
    return unwrapped, modulus, wraps


def _wraps(wraps: int, modulus: int) -> str:
    at = "2^32" if modulus == MODULUS_32_BIT else "one day (864e6 ticks)"
    return f"unwrapped at {at}: {wraps} wrap{'s' if wraps != 1 else ''}"
