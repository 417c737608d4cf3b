"""CSV text as spreadsheets and lab tools write it, read into numeric columns.

Excel alone writes four dialects of "CSV": comma-separated (``CSV``), the same with a UTF-8 byte-order
mark (``CSV UTF-8``), semicolon-separated with decimal commas (every European locale) and tab-separated
(``Text``), all with CRLF line ends. ``sniff`` tells them apart from the first lines; ``read_table``
parses the rows with numpy's C reader (``np.loadtxt`` streaming the lines: a 10^7-row file in seconds
and only its columns in memory) and falls back to a row-by-row reading that
finds empty cells (NaN) and names the row and column of a value that is not a number. Text columns
(dates, comments, a run label) are left out unless they are asked for.
"""

from __future__ import annotations

import codecs
import csv
import math
import re
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import InputError

#: Separators tried, in order: a semicolon or tab file may hold decimal commas, a comma file cannot.
SEPARATORS = ("\t", ";", ",")
SEPARATOR_NAMES = {"\t": "tab", ";": "semicolon", ",": "comma"}
#: Lines read to tell the dialect and which columns are numbers.
SNIFF_LINES = 200
_DECIMAL_COMMA = re.compile(r"^\s*[+-]?\d*,\d+([eE][+-]?\d+)?\s*$")
_BOMS = ((codecs.BOM_UTF8, "utf-8-sig"), (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16"))


@dataclass(frozen=True)
class Dialect:
    """How one CSV file is written."""

    separator: str = ","
    decimal_comma: bool = False
    encoding: str = "utf-8"
    crlf: bool = False

    @property
    def plain(self) -> bool:
        """Comma-separated, decimal points, no byte-order mark (CRLF or not): nothing worth saying."""
        return self.separator == "," and not self.decimal_comma and self.encoding == "utf-8"

    def describe(self) -> str:
        parts = [f"{SEPARATOR_NAMES[self.separator]}-separated"]
        if self.decimal_comma:
            parts.append("decimal commas")
        if self.encoding != "utf-8":
            names = {"utf-8-sig": "UTF-8 byte-order mark", "utf-16": "UTF-16", "cp1252": "Windows-1252 text"}
            parts.append(names[self.encoding])
        if self.crlf:
            parts.append("CRLF line ends")
        return ", ".join(parts)


@dataclass
class CsvTable:
    """The numeric columns of a CSV file, its leading ``#`` comment lines and how it was written."""

    columns: dict[str, np.ndarray]
    comments: list[str]
    dialect: Dialect
    ignored: list[str]  # text columns left out


def _encoding(head: bytes) -> str:
    """A byte-order mark's encoding; else UTF-8, or Windows-1252 where the bytes are not UTF-8 (Excel's
    plain "CSV" on Windows writes ``°`` as one byte)."""
    marked = next((name for bom, name in _BOMS if head.startswith(bom)), None)
    if marked is not None:
        return marked
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        return "utf-8" if exc.start >= len(head) - 3 else "cp1252"  # a character cut by the 64 kB read
    return "utf-8"


def _open(path: Path, encoding: str) -> Iterator[str]:
    """The file's lines without their line ends (CRLF, LF or CR: Python's universal newlines)."""
    with path.open(encoding=encoding, newline=None) as fh:
        for line in fh:
            yield line.rstrip("\n")


def _split(line: str, separator: str) -> list[str] | None:
    """The cells of one line; None where the csv module refuses it (a cell over its 128 kB limit, a NUL
    byte): no table a lab writes has such a cell, so that separator is not the file's."""
    try:
        return next(csv.reader([line], delimiter=separator))
    except csv.Error:
        return None


def _cells(path: Path, line: str, separator: str, row: str) -> list[str]:
    """The cells of ``row`` (its name in the message), or one line saying why it is not a CSV row."""
    cells = _split(line, separator)
    if cells is None:
        raise InputError(
            f"{path}: {row} ({len(line)} characters) is not a {SEPARATOR_NAMES[separator]}-separated row "
            "of a table; export the data again, one sample per line"
        )
    return cells


def sniff(path: Path) -> tuple[Dialect, list[str], list[str], list[list[str]]]:
    """The dialect, the leading comment lines, the header names and the first data rows (as text)."""
    with path.open("rb") as fh:
        head = fh.read(1 << 16)
    encoding = _encoding(head)
    lines: list[str] = []
    comments: list[str] = []
    try:
        for line in _open(path, encoding):
            if not line.strip():
                continue
            if line.startswith("#") and not lines:
                comments.append(line)
                continue
            lines.append(line)
            if len(lines) > SNIFF_LINES:
                break
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as CSV text ({exc})") from None
    if not lines:
        raise InputError(f"{path}: no header line and no data: not a CSV table")
    separator = _separator(path, lines)
    header = [name.strip() for name in _cells(path, lines[0], separator, "the header")]
    rows = [_cells(path, line, separator, f"data line {i}") for i, line in enumerate(lines[1:], start=1)]
    decimal_comma = separator != "," and any(_DECIMAL_COMMA.match(c) for row in rows for c in row)
    crlf = b"\r\n" in head or b"\r\x00\n" in head
    return Dialect(separator, decimal_comma, encoding, crlf), comments, header, rows


def _separator(path: Path, lines: list[str]) -> str:
    """The first separator that splits the header into two or more names and every row alike."""
    for separator in SEPARATORS:
        widths = {len(cells) if (cells := _split(line, separator)) is not None else 0 for line in lines}
        if len(widths) == 1 and widths.pop() >= 2:
            return separator
    for separator in SEPARATORS:  # a ragged file: the header's separator, and the rows are checked later
        if len(_split(lines[0], separator) or ()) >= 2:
            return separator
    raise InputError(
        f"{path}: cannot tell how the columns are separated (tried comma, semicolon and tab); "
        f"the header is {lines[0][:60]!r}"
    )


def to_float(cell: str, decimal_comma: bool) -> float:
    """One cell as a number (empty: NaN); ValueError when it is not one."""
    cell = cell.strip()
    if not cell:
        return math.nan
    return float(cell.replace(",", ".") if decimal_comma else cell)


def _is_number(cell: str, decimal_comma: bool) -> bool:
    try:
        to_float(cell, decimal_comma)
    except ValueError:
        return False
    return True


def read_table(path: Path, wanted: Sequence[str] = (), skip_rows: int = 0) -> CsvTable:
    """The numeric columns of ``path`` (columns named in ``wanted`` must be numbers; other text columns
    are left out and listed); ``skip_rows`` data rows after the header are not read (an export's units)."""
    dialect, comments, header, rows = sniff(path)
    rows = rows[skip_rows:]
    # a nameless empty column is the separator Excel puts at the end of every row: not a column at all
    blank = [not any(row[i].strip() for row in rows if i < len(row)) for i in range(len(header))]
    empty = {i for i, name in enumerate(header) if not name and blank[i]}
    numeric = [
        i
        for i, name in enumerate(header)
        if i not in empty
        and (name in wanted or all(_is_number(row[i], dialect.decimal_comma) for row in rows if i < len(row)))
    ]
    try:
        data = _load_fast(path, dialect, len(comments) + 1 + skip_rows, numeric)
        if data is None and dialect.separator != "," and not dialect.decimal_comma:  # commas after the sniff
            dialect = replace(dialect, decimal_comma=True)
            data = _load_fast(path, dialect, len(comments) + 1 + skip_rows, numeric)
        if data is None:
            data, numeric = _load_checked(path, dialect, header, 1 + skip_rows, numeric, wanted)
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as CSV text ({exc})") from None
    columns = {header[i]: data[:, j] for j, i in enumerate(numeric)}
    ignored = [name for i, name in enumerate(header) if i not in numeric and i not in empty]
    return CsvTable(columns, comments, dialect, ignored)


def _load_fast(path: Path, dialect: Dialect, skip: int, columns: list[int]) -> np.ndarray | None:
    """numpy's C reader on the file from its first data row (``skip`` non-blank lines in: comments,
    header, units row); None when a row needs the careful reading."""
    with path.open(encoding=dialect.encoding, newline=None) as fh:
        while skip:
            line = fh.readline()
            if not line:
                break
            skip -= bool(line.strip())
        lines = (line.replace(",", ".") for line in fh) if dialect.decimal_comma else fh
        try:
            with warnings.catch_warnings():  # a file with no data rows: the caller says so in one line
                warnings.simplefilter("ignore", UserWarning)
                return np.loadtxt(
                    lines,
                    delimiter=dialect.separator,
                    usecols=columns,
                    dtype=float,
                    comments="#",
                    ndmin=2,
                    quotechar='"',
                ).reshape(-1, len(columns))
        except (ValueError, IndexError):
            return None


def _load_checked(
    path: Path, dialect: Dialect, header: list[str], skip: int, columns: list[int], wanted: Sequence[str]
) -> tuple[np.ndarray, list[int]]:
    """Row by row: empty cells are NaN; a text value in a column asked for is one line naming its row
    and column, in any other column it leaves that column out. Returns the values and their columns."""
    values: list[list[float]] = []
    text: set[int] = set()
    seen = 0
    for row_number, line in enumerate(_open(path, dialect.encoding), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        seen += 1
        if seen <= skip:
            continue
        cells = _cells(path, line, dialect.separator, f"row {row_number}")
        if len(cells) != len(header):
            raise InputError(
                f"{path}: row {row_number} has {len(cells)} fields, the header {len(header)} "
                f"({SEPARATOR_NAMES[dialect.separator]}-separated)"
            )
        row = []
        for i in columns:
            try:
                row.append(to_float(cells[i], dialect.decimal_comma))
            except ValueError:
                if header[i] in wanted:
                    raise InputError(
                        f"{path}: row {row_number}, column {header[i]!r}: {cells[i].strip()[:30]!r} is not "
                        "a number"
                    ) from None
                text.add(i)
                row.append(math.nan)
        values.append(row)
    data = np.array(values, dtype=float).reshape(-1, len(columns))
    keep = [j for j, i in enumerate(columns) if i not in text]
    return data[:, keep], [columns[j] for j in keep]
