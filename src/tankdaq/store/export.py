"""Recordings out to the tools labs use: CSV (pandas, Excel, MATLAB ``readtable``, ``tankdaq identify``),
HDF5 (h5py, one file per decay), Parquet (pyarrow) and MATLAB .mat.

A table is time, the decay axis' angle and rate, then every other sample field, in the SI units the
recording holds (names in ``store.export_layout``), with the run metadata as typed values (numbers as
numbers, lists as lists). ``--frame release`` (the default) puts t = 0 at the release and keeps the
device clock as ``device_time_s``; ``release_t_s`` in the metadata lists the releases in the file's time
frame, so ``store.csv_import`` cuts the runs exactly where the recording's release events put them.
Writers are picked by format name (also the suffix) from ``WRITERS``, the way python-can picks log
writers by suffix; ``PER_DECAY`` formats write one file per release, as labs store one file per run.
"""

from __future__ import annotations

import glob
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum
from pathlib import Path

import numpy as np

from ..config.validation import refuse_existing
from ..errors import BadRecordingInput, InputError, install_hint
from ..samples import AXIS_FIELDS, SAMPLE_UNITS
from .export_layout import (
    DEVICE_TIME_COLUMN,
    EXPORT_FORMAT,
    TIME_COLUMN,
    ExportTable,
    column_name,
    sidecar_path,
)
from .export_writers import write_csv, write_h5, write_mat, write_parquet
from .reader import (
    StoredRecording,
    _finite_increasing,
    _release_times,
    corruption_notice,
    read_recording,
    truncation_notice,
)
from .schemas import TOPIC_SAMPLES


class TimeFrame(StrEnum):
    """Where an export's time starts: at the release (the default: people read time since it) or as the
    device clock has it."""

    RELEASE = "release"
    DEVICE = "device"


#: The frames as ``--frame`` takes them; the first is the default.
FRAMES = tuple(frame.value for frame in TimeFrame)
#: Run metadata that stays text even when it reads as a number (an id, a draft like ``1.1T``).
TEXT_KEYS = frozenset(
    {"hull", "hull_description", "draft", "axis", "device_id", "product_code", "firmware", "software_version",
     "operator", "note"}
)  # fmt: skip


#: Writer by format name; the format name is also the file suffix. Each returns the files it wrote.
WRITERS: dict[str, Callable[[ExportTable, Path], list[Path]]] = {
    "csv": write_csv,
    "h5": write_h5,
    "parquet": write_parquet,
    "mat": write_mat,
}
#: Formats written as one file per decay (``<stem>_decay<k>``), the way a lab's run database holds runs.
PER_DECAY = frozenset({"h5"})
#: What a format needs beyond the core install, and the line that says how to get it.
EXTRAS = {"parquet": ("pyarrow", f"parquet export needs pyarrow: {install_hint('parquet')}")}


def check_options(file_format: str, frame: str) -> None:
    """Format and frame are known and the format's library is installed (one line each, exit 2)."""
    if file_format not in WRITERS:
        raise InputError(f"format {file_format!r} not understood: use {', '.join(WRITERS)}")
    if frame not in FRAMES:
        raise InputError(f"frame {frame!r} not understood: use {' or '.join(FRAMES)}")
    if file_format in EXTRAS:
        module, line = EXTRAS[file_format]
        try:
            __import__(module)
        except ImportError:
            raise InputError(line) from None


def typed_metadata(metadata: dict[str, str]) -> dict[str, object]:
    """A recording's metadata strings as the values they stand for (``"6"`` -> 6, a JSON list -> list);
    names, ids and drafts stay text; a value that is no finite number stays text."""
    text_keys = {key for key in metadata if key in TEXT_KEYS or key.endswith("_utc")}
    return {key: text if key in text_keys else _typed(text) for key, text in metadata.items()}


def _typed(text: str) -> object:
    try:
        return json.loads(text, parse_constant=lambda _: text)
    except json.JSONDecodeError:
        return text


@dataclass(frozen=True)
class _Usable:
    """A recording, its samples with finite time, angle and rate (time increasing), its releases."""

    recording: StoredRecording
    samples: np.ndarray
    releases: list[float]

    @property
    def dropped_rows(self) -> int:
        return int(self.recording.samples.size - self.samples.size)


def recording_table(path: str | Path, frame: str = FRAMES[0]) -> ExportTable:
    """The export table of one recording; ``frame='release'`` puts t = 0 at the first release (a
    recording without a release keeps the device clock, and its metadata says ``frame: device``)."""
    usable = _usable(path, frame)
    return _table(usable, usable.samples, None, usable.recording.path.stem, frame)


def decay_tables(path: str | Path, frame: str = FRAMES[0]) -> list[ExportTable]:
    """One table per release, from the release to the next, t = 0 at its release (``frame='release'``);
    the first also holds what came before its release (negative times), so no sample is left out."""
    usable = _usable(path, frame)
    stem = usable.recording.path.stem
    if len(usable.releases) < 2:
        return [_table(usable, usable.samples, None, stem, frame)]
    parts = np.split(usable.samples, np.searchsorted(usable.samples["t"], usable.releases[1:], side="left"))
    return [_table(usable, part, k, f"{stem}_decay{k + 1}", frame) for k, part in enumerate(parts)]


def _usable(path: str | Path, frame: str) -> _Usable:
    if frame not in FRAMES:
        raise InputError(f"frame {frame!r} not understood: use {' or '.join(FRAMES)}")
    recording = read_recording(path)
    angle_field, rate_field = AXIS_FIELDS[recording.axis]
    samples = recording.samples
    samples = samples[_finite_increasing(samples["t"], samples[angle_field], samples[rate_field])]
    if samples.size == 0:
        raise BadRecordingInput(
            f"{recording.path}: no sample with a finite time, {recording.axis} angle and rate: nothing to "
            f"export (a tankdaq recording holds them on {TOPIC_SAMPLES})"
        )
    return _Usable(recording, samples, _release_times(recording.events))


def _table(usable: _Usable, samples: np.ndarray, decay: int | None, name: str, frame: str) -> ExportTable:
    """Columns of ``samples`` with t = 0 at release number ``decay`` (the first when None: the whole
    recording) in the release frame; the metadata lists the releases the table holds."""
    recording = usable.recording
    axis = recording.axis
    frame = frame if usable.releases else TimeFrame.DEVICE.value  # plain text: it goes into the files
    held = usable.releases if decay is None else usable.releases[decay : decay + 1]
    origin = held[0] if frame == TimeFrame.RELEASE else 0.0
    angle_field, rate_field = AXIS_FIELDS[axis]
    fields = [angle_field, rate_field]
    fields += [f for f in samples.dtype.names or () if f not in (*fields, "t")]
    columns = {TIME_COLUMN: samples["t"] - origin}
    units = {TIME_COLUMN: "s"}
    if frame == TimeFrame.RELEASE:
        columns[DEVICE_TIME_COLUMN], units[DEVICE_TIME_COLUMN] = samples["t"].copy(), "s"
    for field in fields:
        columns[column_name(field)] = samples[field].copy()
        units[column_name(field)] = SAMPLE_UNITS[field]
    meta = typed_metadata(recording.metadata)
    nominal = meta.get("angle_nominal_deg")
    metadata: dict[str, object] = {
        "format": EXPORT_FORMAT,
        **meta,
        "source": str(recording.path),
        "axis": axis,
        "frame": frame,
        "time_origin_s": origin,
        "release_t_s": [r - origin for r in held],
        "dropped_rows": usable.dropped_rows,
        "complete_file": recording.complete,
        **({"corruption": recording.corruption} if recording.corruption else {}),
    }
    if isinstance(nominal, int | float) and math.isfinite(nominal):  # the campaign's label sidecar key
        metadata["angle_deg"] = float(nominal)
    return ExportTable(name, columns, units, metadata)


def export_recording(
    path: str | Path,
    file_format: str,
    out_dir: Path | None = None,
    frame: str = FRAMES[0],
    on_notice: Callable[[str], None] | None = None,
) -> list[Path]:
    """Write one recording as ``<out_dir>/<stem>.<format>`` (default beside it; one file per decay for
    ``PER_DECAY`` formats, a ``<stem>.json`` sidecar beside a CSV); returns the paths written.

    Never over a file (``store.safe_write``): a name that exists is refused before anything is written;
    a failure (a full disk) removes what this call wrote, so a recording is exported whole or not at all.

    ``on_notice`` hears the lines the user should read: the recording is cut short, or holds no release
    (its times stay device time).
    """
    check_options(file_format, frame)
    tables = decay_tables(path, frame) if file_format in PER_DECAY else [recording_table(path, frame)]
    if on_notice is not None:
        corruption = tables[0].metadata.get("corruption")
        if isinstance(corruption, str):
            on_notice(corruption_notice(path, corruption))
        elif not tables[0].metadata["complete_file"]:
            on_notice(truncation_notice(path))
        if frame == TimeFrame.RELEASE and tables[0].metadata["frame"] == TimeFrame.DEVICE:
            on_notice(f"{path}: no release recorded, so its times are the device clock (--frame device)")
    if file_format in PER_DECAY and len(tables) > 1:  # each decay file says which decay it holds
        tables = [
            replace(table, metadata={**table.metadata, "decay": k, "decays": len(tables)})
            for k, table in enumerate(tables, start=1)
        ]
    folder = out_dir if out_dir is not None else Path(path).parent
    targets = [folder / f"{table.name}.{file_format}" for table in tables]
    refuse_existing([*targets, *(sidecar_path(t) for t in targets if file_format == "csv")])
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write into {folder}: {exc.strerror or exc}") from None
    written: list[Path] = []
    try:
        for table, target in zip(tables, targets, strict=True):
            written += WRITERS[file_format](table, target)
    except BaseException:
        for done in written:  # this call's own files: a recording is exported whole or not at all
            done.unlink(missing_ok=True)
        raise
    return written


def check_targets(paths: Sequence[Path], file_format: str, out_dir: Path | None) -> None:
    """Before anything is written: no two recordings export to one name (one stem into one folder,
    whatever the case: one would be lost under the other), and no export's name is taken (a
    ``PER_DECAY`` format's ``<stem>_decay<k>`` too, whatever the count of decays)."""
    seen: dict[tuple[Path, str], Path] = {}
    for path in paths:
        folder = (out_dir if out_dir is not None else path.parent).resolve()
        target = folder / f"{path.stem}.{file_format}"
        taken = [target, sidecar_path(target)] if file_format == "csv" else [target]
        if file_format in PER_DECAY:
            taken += sorted(folder.glob(f"{glob.escape(path.stem)}_decay*.{file_format}"))
        refuse_existing(taken)
        first = seen.setdefault((folder, path.stem.casefold()), path)
        if first is not path:
            why = "is given twice" if first.resolve() == path.resolve() else f"and {first} would both export"
            raise InputError(
                f"{path} {why} to {folder / path.stem}.*: give each once, or export recordings of one name "
                "into different --out folders"
            )
