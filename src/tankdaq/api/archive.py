"""A lab's archive converted: every decay in every file of a folder, each written as a tankdaq recording
with where it came from (``tankdaq import FOLDER --out recordings/``; ``catalogue.archive`` catalogues
what this writes).

Every file ``store.inputs`` reads (recordings, CSV, HDF5, MATLAB, Parquet, LabVIEW TDMS, MT Manager logs
and text exports) is read through the one way in (``ident.inputs.read_decays``: several decays per log are
found as ``identify`` finds them); each decay becomes one MCAP named by its source's SHA-256 and its place
in the file (``<stem>-<sha12>-<n>.mcap``), so importing again finds it there and adds nothing. A
recording's metadata keeps the provenance: the source file, its SHA-256, its format, the decay's index,
what the reader read from the file's header, and the conversions made (units, time, what was skipped). A
file is written under a temporary name and published (``store.safe_write``); a file of that name that
tankdaq's import did not write is never replaced, and said. Files that are no decays are listed with why.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, TankdaqError
from ..records import DecayRun
from ..samples import AXIS_FIELDS, empty_samples
from . import arguments
from .progress import Progress, Quiet

#: The run metadata keys an imported decay's provenance is kept under (``store.schemas.RUN_METADATA_KEYS``).
SOURCE_KEYS = (
    "source_file",
    "source_sha256",
    "source_format",
    "source_decay",
    "source_header",
    "conversions",
)
#: Keys of a reader's ``meta`` that are not the source file's header (tankdaq's own bookkeeping).
_NOT_HEADER = frozenset({"notices", "sha256", "file", "cut", "find_releases"})


@dataclass(frozen=True)
class ImportedDecay:
    """One decay of a source file and the recording that holds it (``added`` False: imported before)."""

    source: Path
    source_sha256: str
    index: int  # 1.. in the source file
    path: Path
    added: bool
    initial_angle_deg: float
    duration_s: float


@dataclass
class ArchiveImport:
    """What an import did: the decays (new and found), the files that are no decays and why, the lines."""

    decays: list[ImportedDecay] = field(default_factory=list)
    not_decays: dict[Path, str] = field(default_factory=dict)
    not_written: list[str] = field(default_factory=list)  # decays found but not written, one line each
    notices: list[str] = field(default_factory=list)

    @property
    def added(self) -> list[ImportedDecay]:
        return [decay for decay in self.decays if decay.added]

    @property
    def line(self) -> str:
        files = len({decay.source for decay in self.decays})
        return (
            f"{len(self.decays)} decays in {files} files: {len(self.added)} written, "
            f"{len(self.decays) - len(self.added)} imported before; {len(self.not_decays)} files not decays"
            + (f"; {len(self.not_written)} decays NOT written" if self.not_written else "")
        )


def import_folder(
    folder: str | Path,
    out: str | Path,
    *,
    axis: str | None = None,
    time_col: str = "time_s",
    angle_col: str = "angle_deg",
    speed_col: str | None = None,
    progress: Progress | None = None,
) -> ArchiveImport:
    """Every decay of every file under ``folder`` as a recording in ``out`` (made where missing); files
    already in ``out`` are not read as sources. Reading settings as ``tankdaq identify``'s."""
    from ..config.validation import output_dir
    from ..store.inputs import INPUT_FORMATS
    from .recording import columns_given

    source = arguments.path(folder, "folder", "the archive folder's path (str or pathlib.Path)")
    if not source.is_dir():
        raise InputError(f"folder: {source} is not a folder: give the folder that holds the lab's files")
    axis, time_col, angle_col, *_ = columns_given(axis, time_col, angle_col, None, None, None)
    speed_col = arguments.optional_text(speed_col, "speed_col", "a column name or None")
    shown = arguments.progress(progress) or Quiet()
    target = output_dir(arguments.path(out, "out", "the recordings folder's path (str or pathlib.Path)"))
    target.mkdir(parents=True, exist_ok=True)
    inside = target.resolve()
    files = sorted(
        p
        for p in source.rglob("*")
        if p.is_file() and not p.name.startswith(".") and inside not in p.resolve().parents
    )
    result = ArchiveImport()
    with shown.task("importing", total=len(files)) as update:
        for done, path in enumerate(files, start=1):
            update(done - 1, description=f"reading {path.name}")
            if _sidecar_of(path, files):
                continue  # read with its decay file (a CSV's labels and metadata)
            if path.suffix.lower() not in INPUT_FORMATS:
                result.not_decays[path] = f"not a file tankdaq reads ({path.suffix or 'no suffix'})"
            else:
                _import_file(path, target, (axis, time_col, angle_col, speed_col), result, shown)
        update(len(files))
    return result


def _sidecar_of(path: Path, files: list[Path]) -> bool:
    """Whether ``path`` is the ``<stem>.json`` beside a decay file of that stem (read with it)."""
    from ..store.inputs import INPUT_FORMATS

    return path.suffix.lower() == ".json" and any(
        path.with_suffix(suffix) in files for suffix in INPUT_FORMATS if suffix != ".json"
    )


def import_file(path: Path, out: Path, progress: Progress | None = None) -> ArchiveImport:
    """The decays of one lab file as recordings in ``out`` (``tankdaq export`` of a file that is not a
    recording: its decays become recordings first, then they are exported); as ``import_folder``."""
    result = ArchiveImport()
    out.mkdir(parents=True, exist_ok=True)
    _import_file(path, out, (None, "time_s", "angle_deg", None), result, progress or Quiet())
    if path in result.not_decays:
        raise InputError(f"{path}: {result.not_decays[path]}")
    if result.not_written:
        raise InputError(result.not_written[0])
    return result


def _import_file(
    path: Path,
    target: Path,
    reading: tuple[str | None, str, str, str | None],
    result: ArchiveImport,
    progress: Progress,
) -> None:
    """The decays of one file into ``target``; a file that holds none goes into ``not_decays`` with why."""
    from ..ident.inputs import input_notices, read_decays
    from ..store.inputs import file_sha256, input_format

    axis, time_col, angle_col, speed_col = reading
    try:
        sha = file_sha256(path)
        runs = read_decays(path, axis, time_col, angle_col, speed_col=speed_col)
    except (TankdaqError, OSError) as exc:
        said = str(exc) if isinstance(exc, TankdaqError) else (exc.strerror or str(exc))
        result.not_decays[path] = said.removeprefix(f"{path}: ").removeprefix(f"{path} ")
        return
    except Exception as exc:  # a library failing on bytes it never expected: one file lost, not the archive
        result.not_decays[path] = f"could not be read ({type(exc).__name__}: {exc})"
        return
    for line in input_notices(runs):
        progress.line(line)
        result.notices.append(line)
    for index, run in enumerate(runs, start=1):
        try:
            result.decays.append(_write_decay(run, path, sha, index, input_format(path).name, target))
        except TankdaqError as exc:
            result.not_written.append(f"{path}: decay {index} not written: {exc}")


def recording_path(target: Path, source: Path, sha: str, index: int) -> Path:
    """Where decay ``index`` of the file of SHA-256 ``sha`` is imported: the same place every time."""
    from ..config.rules import safe_name

    stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in source.stem)[:40] or "decay"
    return target / f"{safe_name(stem, 'file name')}-{sha[:12]}-{index}.mcap"


def _write_decay(run: DecayRun, source: Path, sha: str, index: int, kind: str, target: Path) -> ImportedDecay:
    """One decay as a recording (its samples from the release, a release event at its first sample)."""
    from ..store.safe_write import new_path
    from ..store.writer import RecordingWriter

    path = recording_path(target, source, sha, index)
    angle_deg, duration = math.degrees(float(run.angle[0])), float(run.t[-1] - run.t[0])
    if path.exists():
        if _imported_from(path) != (sha, index):
            raise InputError(
                f"{path} exists and is not this decay's import: left alone (move it, import again)"
            )
        return ImportedDecay(source, sha, index, path, False, angle_deg, duration)
    metadata = _metadata(run, source, sha, index, kind)
    config = {"imported": {key: metadata[key] for key in SOURCE_KEYS}}
    with new_path(path) as temporary, RecordingWriter(temporary, metadata, config) as writer:
        writer.write_samples(_samples(run))
        writer.write_event("release", f"decay {index} of {source.name}", t_s=float(run.t[0]))
    return ImportedDecay(source, sha, index, path, True, angle_deg, duration)


def _imported_from(path: Path) -> tuple[str, int] | None:
    """(source SHA-256, decay index) of a recording an import wrote; None for any other file."""
    from ..store.reader import read_recording

    try:
        meta = read_recording(path).metadata
        return str(meta["source_sha256"]), int(str(meta["source_decay"]))
    except (TankdaqError, KeyError, ValueError):
        return None


def _metadata(run: DecayRun, source: Path, sha: str, index: int, kind: str) -> dict[str, object]:
    """The run metadata of an imported decay: the condition where known, the device, the provenance."""
    from ..campaign.groups import csv_labels
    from ..config.hulls import format_draft
    from ..store.csv_import import NOTICES
    from ..store.inputs import RECORDING_FORMAT

    meta = run.meta
    try:
        labels = csv_labels(source) if kind != RECORDING_FORMAT else {}
    except InputError:
        labels = {}
    nominal = labels.get("angle_deg", meta.get("angle_nominal_deg"))
    measured = round(abs(math.degrees(float(run.angle[0]))), 1)
    described: dict[str, object] = {"axis": run.axis, "angle_nominal_deg": float(nominal or measured)}
    for key in ("hull", "draft"):
        value = meta.get(key, labels.get(key))
        if value is not None:  # a draft as a recording writes it (1.1T), from the factor read
            described[key] = format_draft(float(value)) if key == "draft" else value
    if run.t.size > 1:
        described["sample_rate_hz"] = round(float(1.0 / np.median(np.diff(run.t))), 6)
    for key in ("device_id", "product_code", "firmware", "speed_m_s", "operator", "note"):
        if meta.get(key) is not None:
            described[key] = meta[key]
    header = {key: value for key, value in meta.items() if key not in _NOT_HEADER and key not in described}
    described |= {
        "source_file": str(source.resolve()),
        "source_sha256": sha,
        "source_format": kind,
        "source_decay": index,
        "source_header": json.dumps(header, default=str, sort_keys=True),
        "conversions": json.dumps(list(meta.get(NOTICES, ())) + _conversions(run, not nominal)),
    }
    return described


def _conversions(run: DecayRun, nominal_unknown: bool) -> list[str]:
    """What the import itself did to the decay, one line each."""
    lines = [f"angle and rate stored in rad and rad/s as the {run.axis} sample fields"]
    if "release_t_s" not in run.meta:  # a record read whole: its decays were found in the data
        lines.append("cut at the release found in the data (ident.inputs), as tankdaq identify cuts it")
    if run.rate is None:
        lines.append("no rate in the source: the rate field is empty (NaN)")
    if nominal_unknown:
        lines.append("angle_nominal_deg: the measured initial angle (the source does not say)")
    return lines


def _samples(run: DecayRun) -> np.ndarray:
    """The decay as sample rows: time (device clock as read), the axis' angle and rate, the other axis'."""
    samples = empty_samples(run.t.size)
    samples["t"] = run.t
    samples["ticks"] = np.round(run.t * 1e4).astype(np.int64)
    samples["counter"] = np.arange(run.t.size) % 65536
    angle_field, rate_field = AXIS_FIELDS[run.axis]
    samples[angle_field] = run.angle
    if run.rate is not None:  # else NaN: read back as a decay without a rate, as its source was
        samples[rate_field] = run.rate
    other = next(name for name in AXIS_FIELDS if name != run.axis)
    for channel, sample_field in ((f"other_angle_{other}", AXIS_FIELDS[other][0]),
                                  (f"other_rate_{other}", AXIS_FIELDS[other][1])):  # fmt: skip
        if channel in run.channels:
            samples[sample_field] = run.channels[channel]
    return samples
