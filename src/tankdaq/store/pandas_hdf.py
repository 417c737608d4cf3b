"""The frames pandas writes to HDF5 (``DataFrame.to_hdf``, through PyTables), read with h5py alone.

A lab that works in Python keeps its runs as ``df.to_hdf("runs.h5", key="run21")``. In the file a frame
is no set of named vectors: the ``fixed`` format (pandas' default) stores each block of same-typed
columns as one matrix (``block0_values``) with its names beside it (``block0_items``); the ``table``
format stores a table of records whose columns are either fields of their own (``data_columns``) or
rows of a block (``values_block_0``) named only in a pickled attribute. Pickles are never loaded here
(loading one runs whatever code it holds): such a list of names is read by walking its opcodes
(``pickletools``), and anything but a plain list of strings is refused. PyTables' own search indexes
(``_i_table``) are no data.
"""

from __future__ import annotations

import pickletools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .export_layout import plain_value

#: Why a dataset, variable or frame column is not a column (``store.column_files`` too).
NOT_A_VECTOR = "is not a vector of numbers"
#: ``pandas_type`` of a frame in the fixed and in the table format.
FRAME_TYPES = (b"frame", b"frame_table")
#: The PyTables class of a table's search indexes (``_i_table``): not data.
INDEX_CLASS = b"TINDEX"
#: A pickled ``None`` (pandas' unnamed index).
PICKLED_NONE = b"N."
#: The opcodes of a pickled list of strings, in any protocol: nothing else is accepted.
LIST_OPCODES = frozenset(
    {
        "PROTO", "FRAME", "MARK", "LIST", "EMPTY_LIST", "PUT", "BINPUT", "LONG_BINPUT", "MEMOIZE",
        "UNICODE", "BINUNICODE", "SHORT_BINUNICODE", "BINUNICODE8", "APPEND", "APPENDS", "STOP",
    }
)  # fmt: skip


@dataclass
class PandasFrame:
    """One pandas frame of a file: its key (its group's path), its numeric columns by the names pandas
    gave them, and what was left out and why."""

    key: str
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    left: dict[str, str] = field(default_factory=dict)


def is_frame(node: Any) -> bool:
    """True for the group of a frame pandas wrote (either format)."""
    return bytes(node.attrs.get("pandas_type", b"")) in FRAME_TYPES


def is_pytables_index(node: Any) -> bool:
    """True for the group of a PyTables table's search indexes (no data of the user's)."""
    return bytes(node.attrs.get("CLASS", b"")) == INDEX_CLASS


def pickled_names(raw: object) -> list[str] | None:
    """The list of strings a pickled attribute holds, read without unpickling; None for anything else."""
    if not isinstance(raw, bytes | np.bytes_):
        return None
    names: list[str] = []
    try:
        for opcode, argument, _ in pickletools.genops(bytes(raw)):
            if opcode.name not in LIST_OPCODES:
                return None
            if isinstance(argument, str):
                names.append(argument)
    except (ValueError, EOFError):  # not a pickle at all
        return None
    return names


def _index(frame: PandasFrame, values: np.ndarray, name: str | None) -> None:
    """The frame's index as a column: by its name, or as ``index`` unless it only numbers the rows."""
    if values.dtype.kind not in "iuf" or values.ndim != 1:
        return
    if name is None and np.array_equal(values, np.arange(values.size)):
        return  # pandas' RangeIndex: row numbers, no data
    frame.columns[name or "index"] = values


def read_fixed(group: Any, key: str) -> PandasFrame:
    """A frame in pandas' fixed format: each ``blockN_values`` matrix cut into its named columns."""
    frame = PandasFrame(key)
    axis = group.get("axis1")
    if axis is not None:
        raw_name = bytes(axis.attrs.get("name", PICKLED_NONE))
        _index(frame, axis[()], None if raw_name == PICKLED_NONE else str(plain_value(raw_name)))
    block = -1
    while f"block{block + 1}_items" in group and f"block{block + 1}_values" in group:  # not ``nblocks``:
        block += 1  # the file's own count, which a damaged file may overstate without end
        items, values = group[f"block{block}_items"], group[f"block{block}_values"]
        names = [str(plain_value(item)) for item in items[()]]
        if values.ndim != 2 or values.dtype.kind not in "biuf" or values.shape[1] != len(names):
            frame.left |= dict.fromkeys(names, NOT_A_VECTOR)
            continue
        matrix = values[()]
        frame.columns |= {name: matrix[:, i] for i, name in enumerate(names)}
    return frame


def read_table(group: Any, key: str) -> PandasFrame:
    """A frame in pandas' table format: its data columns, and each ``values_block_N`` cut into the
    columns its attribute names."""
    frame = PandasFrame(key)
    table = group.get("table")
    if table is None or not table.dtype.names:
        return frame
    records = table[()]
    for name in table.dtype.names:
        values = records[name]
        if name == "index":
            _index(frame, values, None)
        elif name.startswith("values_block_"):
            names = pickled_names(table.attrs.get(f"{name}_kind"))
            if names is None or values.ndim != 2 or values.shape[1] != len(names):
                frame.left[name] = (
                    "is a block of columns whose names are no plain list (a pickle that was not loaded)"
                )
            elif values.dtype.kind not in "biuf":
                frame.left |= dict.fromkeys(names, NOT_A_VECTOR)
            else:
                frame.columns |= {column: values[:, i] for i, column in enumerate(names)}
        elif values.ndim == 1 and values.dtype.kind in "biuf":
            frame.columns[name] = values
        else:
            frame.left[name] = NOT_A_VECTOR
    return frame


def read_frame(group: Any, key: str) -> PandasFrame:
    """A frame pandas wrote, in either format."""
    fixed = bytes(group.attrs.get("pandas_type", b"")) == b"frame"
    return read_fixed(group, key) if fixed else read_table(group, key)
