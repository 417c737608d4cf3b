"""The names an exported recording's files use, shared by ``store.export`` (writing) and
``store.csv_import`` (reading an exported CSV back).

Columns are the sample fields of ``samples.SAMPLE_DTYPE`` with their SI unit as a suffix (``roll_rad``,
``p_rad_s``, ``az_m_s2``): the MCAP archive's values unchanged, so a file holds the recording to the last
bit, and one name whatever the tool (pandas, Excel, MATLAB, h5py). The run metadata travels beside a CSV
as ``<stem>.json`` (also the campaign's label sidecar: hull, draft, axis, angle_deg), inside HDF5 as
root attributes and inside Parquet as schema metadata, always marked ``"format": EXPORT_FORMAT``.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..samples import AXIS_FIELDS, SAMPLE_UNITS

#: ``format`` in an export's metadata: how a reader tells a tankdaq export's sidecar from any JSON.
EXPORT_FORMAT = "tankdaq export"
#: Time column: time since the release (``--frame release``) or the device clock (``--frame device``).
TIME_COLUMN = "time_s"
#: The device clock beside time since release, so the recording's own times stay in the file exactly.
DEVICE_TIME_COLUMN = "device_time_s"
#: Column suffix of each SI unit: the suffix ``csv_import`` reads the unit from.
UNIT_SUFFIX = {"s": "s", "rad": "rad", "rad/s": "rad_s", "m/s^2": "m_s2"}


def column_name(field: str) -> str:
    """The export column of a sample field: the field and its unit's suffix (``p`` -> ``p_rad_s``)."""
    unit = SAMPLE_UNITS[field]
    return f"{field}_{UNIT_SUFFIX[unit]}" if unit in UNIT_SUFFIX else field


def axis_columns(axis: str) -> tuple[str, str]:
    """The angle and rate columns of a decay axis (``roll`` -> ``roll_rad``, ``p_rad_s``)."""
    angle, rate = AXIS_FIELDS[axis]
    return column_name(angle), column_name(rate)


def sidecar_path(path: Path) -> Path:
    """Where an exported CSV's metadata is: ``<stem>.json`` beside it."""
    return path.with_suffix(".json")


def read_sidecar(path: Path) -> dict[str, object] | None:
    """The metadata of an exported CSV from its sidecar; None when there is none or it is not a tankdaq
    export's (a campaign label sidecar, another tool's JSON): then the CSV is read as any other."""
    sidecar = sidecar_path(path)
    try:
        data = json.loads(sidecar.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(data, dict) or data.get("format") != EXPORT_FORMAT:
        return None
    return data


@dataclass
class ExportTable:
    """Columns (name -> values, names carry the unit suffix), their units, and the run metadata."""

    name: str
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    metadata: dict[str, object]


def read_h5_metadata(path: Path) -> dict[str, object] | None:
    """The metadata of an HDF5 file ``tankdaq export`` wrote (its root attributes); None for another
    tool's HDF5 file. A file HDF5 cannot open raises ``OSError``."""
    import h5py

    with h5py.File(path, "r") as h5:
        found = {key: plain_value(h5.attrs[key]) for key in h5.attrs}
    return found if found.get("format") == EXPORT_FORMAT else None


def plain_value(value: object) -> object:
    """A value read from HDF5 or MATLAB as JSON would hold it: arrays as lists, numpy scalars as
    numbers, bytes as text."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return [plain_value(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_parquet_metadata(path: Path) -> dict[str, object] | None:
    """The metadata of a Parquet file ``tankdaq export`` wrote (the JSON under its schema metadata key
    ``tankdaq``, read from the footer alone); None for another tool's Parquet file. Needs pyarrow
    (``ImportError`` without it); a file pyarrow cannot read raises ``OSError`` or ``ValueError``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        text = (pq.read_schema(path).metadata or {}).get(b"tankdaq")
    except pa.ArrowException as exc:  # not a Parquet file, or one of a kind pyarrow does not read
        raise ValueError(str(exc)) from None
    try:
        found = json.loads(text) if text is not None else None
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    return found if isinstance(found, dict) and found.get("format") == EXPORT_FORMAT else None


def read_mat_metadata(path: Path) -> dict[str, object] | None:
    """The metadata of a MATLAB file ``tankdaq export`` wrote (its struct ``tankdaq``'s ``meta``, the lists
    and booleans written as JSON text read back); None for another tool's .mat file. A file scipy
    cannot read raises ``ValueError`` or ``OSError``."""
    from scipy.io import loadmat, whosmat

    try:
        if not any(name == "tankdaq" for name, _shape, kind in whosmat(path) if kind == "struct"):
            return None  # whosmat reads the variables' headers only: another tool's file is not loaded
        struct = loadmat(path, variable_names=["tankdaq"], simplify_cells=True)["tankdaq"]
    except OSError:
        raise
    except Exception as exc:  # scipy fails in many ways on bytes that are no MATLAB file (IndexError...)
        raise ValueError(f"{type(exc).__name__}: {exc}") from None
    return mat_export_meta(struct.get("meta") if isinstance(struct, dict) else None)


def mat_export_meta(meta: object) -> dict[str, object] | None:
    """An export's ``tankdaq.meta`` struct as JSON would hold it (the values ``store.export_writers``
    wrote as JSON text, lists and booleans, read back); None when it is not an export's."""
    if not isinstance(meta, dict) or meta.get("format") != EXPORT_FORMAT:
        return None
    found: dict[str, object] = {}
    for key, value in meta.items():
        if isinstance(value, str) and (value[:1] in ("[", "{") or value in ("true", "false")):
            with contextlib.suppress(json.JSONDecodeError):
                value = json.loads(value)
        found[str(key)] = plain_value(value)
    return found


#: How an export's metadata is read, by the file's suffix (lower case); a recording has none.
METADATA_READERS: dict[str, Callable[[Path], dict[str, object] | None]] = {
    ".csv": read_sidecar,
    ".h5": read_h5_metadata,
    ".hdf5": read_h5_metadata,
    ".parquet": read_parquet_metadata,
    ".mat": read_mat_metadata,
}


def export_metadata_of(path: Path) -> dict[str, object] | None:
    """The metadata of any file ``tankdaq export`` wrote (a CSV's sidecar, HDF5 root attributes, Parquet
    schema metadata, a .mat file's ``tankdaq.meta``); None for a recording, another tool's file, or one
    that cannot be read here (its reader says why when the decays are read)."""
    reader = METADATA_READERS.get(path.suffix.lower())
    try:
        return reader(path) if reader is not None else None
    except (ImportError, OSError, ValueError, TypeError, KeyError):
        return None


@dataclass(frozen=True)
class ExportOrigin:
    """Which decays an export holds: its recording (``source`` as given to ``tankdaq export``, and the
    recording's ``created_utc``) and its releases on the device clock (ms), so two exports of one
    recording (HDF5 and MATLAB, or renamed) are known as the same decays."""

    source: str
    created_utc: str
    releases: frozenset[float]

    @classmethod
    def of(cls, meta: Mapping[str, object] | None) -> ExportOrigin | None:
        """The origin an export's metadata gives; None for any other file's, or an edited one's."""
        if meta is None or meta.get("format") != EXPORT_FORMAT:
            return None
        source, created, origin = meta.get("source"), meta.get("created_utc"), meta.get("time_origin_s", 0.0)
        releases = meta.get("release_t_s")
        if not (isinstance(source, str) and source and isinstance(created, str)):
            return None
        if not isinstance(releases, list):
            return None
        try:
            held = frozenset(round(float(origin) + float(r), 3) for r in releases)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            return None
        return cls(source, created, held)

    def same_recording(self, other: ExportOrigin) -> bool:
        return Path(self.source).name == Path(other.source).name and self.created_utc == other.created_utc


def exports_read_twice(
    paths: Sequence[Path], origins: Mapping[Path, ExportOrigin | None] | None = None
) -> dict[Path, str]:
    """The exports among ``paths`` (any format) whose decays another file among them holds, each with
    why. Read both, each decay would count twice: as a repeat, narrowing every interval.

    - An export of a recording that is among them: it names its recording (``source``), found at that
      path or by that name in the export's own folder (``export`` writes beside each recording).
    - An export of the same decays as an earlier one (the recording exported to HDF5 and MATLAB, or a
      copy renamed): the one holding the most decays is kept.

    ``origins``: each file's ``ExportOrigin`` where the caller has it (a campaign's workers read it as
    they scan); else read here from each file's metadata."""
    if origins is None:
        origins = {path: ExportOrigin.of(export_metadata_of(path)) for path in paths}
    recordings = {path.resolve(): path for path in paths if path.suffix.lower() == ".mcap"}
    twice: dict[Path, str] = {}
    exported = [(path, origin) for path in paths if (origin := origins.get(path)) is not None]
    for path, origin in exported:
        for candidate in (Path(origin.source), path.parent / Path(origin.source).name):
            recording = recordings.get(candidate.resolve())
            if recording is not None:
                twice[path] = f"is the export of {recording}"
                break
    kept: list[tuple[Path, ExportOrigin]] = []
    for path, origin in sorted(exported, key=lambda found: -len(found[1].releases)):
        if path in twice:
            continue
        first = next((p for p, o in kept if o.same_recording(origin) and origin.releases <= o.releases), None)
        if first is not None:
            twice[path] = f"holds the same decays as {first} (exports of {Path(origin.source).name})"
        else:
            kept.append((path, origin))
    return twice
