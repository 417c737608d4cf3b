"""The file writers of ``store.export``: each takes an export table and a path, and returns the files it
wrote, each new (``store.safe_write``: never over a file, never half-written under its name). Values
are written as the recording holds them (float64 to the last bit, integers as integers), so reading a
file back gives the recording's samples exactly.
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from .export_layout import ExportTable, sidecar_path
from .safe_write import write_new, write_text_new


def json_ready(value: object) -> object:
    """A metadata value JSON writes as strict JSON: a non-finite number becomes null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, list):
        return [json_ready(v) for v in value]
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    return value


def _cells(values: np.ndarray) -> list[str]:
    """A column as CSV cells: floats by repr (the shortest text that reads back to the same float), an
    empty cell for NaN (what pandas, Excel and readtable read as missing), integers as integers."""
    if values.dtype.kind == "f":
        return ["" if math.isnan(x) else repr(x) for x in values.tolist()]
    return [str(x) for x in values.tolist()]


def write_csv(table: ExportTable, path: Path) -> list[Path]:
    """One header row (names with units), one row per sample; the metadata in ``<stem>.json``."""
    cells = [_cells(values) for values in table.columns.values()]

    def rows(out: BinaryIO) -> None:
        out.write((",".join(table.columns) + "\n").encode("ascii"))
        out.writelines((",".join(row) + "\n").encode("ascii") for row in zip(*cells, strict=True))

    write_new(path, rows)
    document = {**table.metadata, "units": table.units}
    try:
        sidecar = write_text_new(
            sidecar_path(path), json.dumps(json_ready(document), indent=2, allow_nan=False) + "\n"
        )
    except BaseException:
        path.unlink()  # this call's own CSV: no export without its metadata
        raise
    return [path, sidecar]


def _attribute(value: object) -> Any:
    """A metadata value as an HDF5 attribute: numbers, text, booleans and lists as themselves (a list of
    numbers as an array); anything else as its JSON text; None as absent."""
    if value is None or isinstance(value, str | bool | int | float):
        return np.bool_(value) if isinstance(value, bool) else value
    if isinstance(value, list) and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        return np.asarray(value, dtype=float)
    if isinstance(value, list) and all(isinstance(v, str) for v in value) and value:
        return value
    return json.dumps(json_ready(value))


def write_h5(table: ExportTable, path: Path) -> list[Path]:
    """One dataset per column with its ``unit`` attribute; the metadata as typed root attributes.

    HDF5 writes into memory and the bytes go to disk in Python: a full disk is one ``OSError`` there,
    never the HDF5 library failing to close a file (its error stack printed, then a segfault)."""
    import h5py

    image = io.BytesIO()
    with h5py.File(image, "w") as out:
        for key, value in table.metadata.items():
            attribute = _attribute(value)
            if attribute is not None:
                out.attrs[key] = attribute
        for name, values in table.columns.items():
            out.create_dataset(name, data=values).attrs["unit"] = table.units[name]
    return [write_new(path, lambda disk: disk.write(image.getbuffer()))]


def write_parquet(table: ExportTable, path: Path) -> list[Path]:
    """One column per field (``unit`` in the field metadata); the metadata as JSON under the schema
    metadata key ``tankdaq``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    fields = [
        pa.field(name, pa.from_numpy_dtype(values.dtype), metadata={"unit": table.units[name]})
        for name, values in table.columns.items()
    ]
    meta = {"tankdaq": json.dumps(json_ready(table.metadata), allow_nan=False)}
    schema = pa.schema(fields, metadata=meta)
    arrays = [pa.array(values, from_pandas=False) for values in table.columns.values()]
    return [write_new(path, lambda out: pq.write_table(pa.Table.from_arrays(arrays, schema=schema), out))]


def write_mat(table: ExportTable, path: Path) -> list[Path]:
    """One struct ``tankdaq`` with the columns, ``units`` and ``meta`` (scipy.io.savemat, MATLAB 5)."""
    from scipy.io import savemat

    meta = {key: json.dumps(value) if isinstance(value, list | dict | bool) else value for key, value in
            table.metadata.items() if value is not None}  # fmt: skip
    struct = {**table.columns, "units": dict(table.units), "meta": meta}
    return [
        write_new(
            path, lambda out: savemat(out, {"tankdaq": struct}, long_field_names=True, oned_as="column")
        )
    ]
