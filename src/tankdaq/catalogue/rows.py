"""What one row holds: a decay file read back (a recording: condition, device, the fit it carries; a
lab's CSV decay: the condition its name or sidecar gives), its SHA-256, a fit's quantities (B_eq and
B̂44 at the standard amplitudes), a hull version, and a file exported from a recording.

Everything here is made from the files, so ``index`` and the live hooks write the same rows.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._version import __version__
from ..config.hulls import Hull, load_hull, locate_hull, parse_draft
from ..errors import RecordingError, TankdaqError, install_hint
from ..records import DecayEnd
from ..store.inputs import INPUT_FORMATS, file_sha256
from ..store.schemas import EventKind
from .database import one_line
from .fits import provenance
from .schema import FitMethod, FitSource, utc_now

#: The amplitudes B_eq and B̂44 are kept at (deg): what a lab compares across campaigns.
STANDARD_AMPLITUDES_DEG = (2.0, 5.0, 10.0)


@dataclass(frozen=True)
class FitHow:
    """How a fit was made: its method, whether the data chose its model (``auto``), its settings."""

    method: FitMethod
    model_by_data: bool = False
    settings: Mapping[str, Any] = field(default_factory=dict)


def _finite(value: object) -> float | None:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def hull_version(hull: Hull) -> dict[str, Any] | None:
    """The hull file as one version (its content hashed), None for a hull made in code."""
    if hull.path is None or not hull.path.is_file():
        return None
    content = hull.path.read_bytes()
    return {
        "sha256": hashlib.sha256(content).hexdigest(),
        "name": hull.name,
        "path": str(hull.path),
        "content": content.decode("utf-8", "replace"),
        "first_seen_utc": utc_now(),
    }


#: Hulls parsed, by their file and its content's SHA-256: the decays of a campaign or a folder name the
#: same few hull files, and parsing one (TOML, every value checked: 1 ms) costs more than the rest of a
#: decay's row; a hull file that changed hashes anew and is parsed again.
_PARSED_HULLS: dict[tuple[str, str], Hull] = {}
MAX_PARSED_HULLS = 64


def find_hull(name: str | None) -> Hull | None:
    """The hull a file names, or None when it is not known here (the row keeps the name)."""
    if not name:
        return None
    try:
        path, _origin = locate_hull(name)
        key = (str(path), hashlib.sha256(path.read_bytes()).hexdigest())
        if key not in _PARSED_HULLS:
            if len(_PARSED_HULLS) >= MAX_PARSED_HULLS:
                _PARSED_HULLS.clear()
            _PARSED_HULLS[key] = load_hull(name)
        return _PARSED_HULLS[key]
    except (TankdaqError, OSError):
        return None


def fit_fields(
    source: FitSource,
    coefficients: Mapping[str, float],
    ci95: Mapping[str, Sequence[float]] | None = None,
    r2_angle: float | None = None,
    warnings: Sequence[str] = (),
    condition: tuple[Hull | None, str | None, str | None] = (None, None, None),
    model: str | None = None,
    how: FitHow | None = None,
) -> dict[str, Any]:
    """A fit as the catalogue keeps it (``fits``): coefficients with their 95 % intervals, period, B_eq
    (and B̂44 for roll, where the hull gives beam and displacement) at ``STANDARD_AMPLITUDES_DEG``, how
    it was made and by whom (``fits.provenance``); ``axis``: the axis fitted, for its decay's row.
    ``condition``: hull, draft, axis."""
    from ..ident.derived import b_eq, natural_period

    how = how or FitHow(FitMethod.UNKNOWN)
    values = {term: float(value) for term, value in coefficients.items()}
    table: dict[str, dict[str, float | None]] = {}
    for term, value in values.items():
        low, high = (ci95 or {}).get(term) or (None, None)
        table[term] = {"value": value, "ci_low": _finite(low), "ci_high": _finite(high)}
    b_eqs = {f"{a:g}": _finite(b_eq(values, math.radians(a))) for a in STANDARD_AMPLITUDES_DEG}
    return {
        "source": source.value,
        "method": how.method.value,
        "model": model or ",".join(values),
        "terms": list(values),
        "model_by_data": how.model_by_data,
        "coefficients": table,
        "natural_period_s": _finite(natural_period(values)),
        "b_eq_per_s": b_eqs,
        "b44_hat": _b44_hat(values, b_eqs, condition),
        "r2_angle": _finite(r2_angle),
        "warnings": list(warnings),
        "settings": dict(how.settings),
        "axis": condition[2],
    } | provenance()


def _b44_hat(
    values: dict[str, float],
    b_eqs: dict[str, float | None],
    condition: tuple[Hull | None, str | None, str | None],
) -> dict[str, float | None] | None:
    """B̂44 at each amplitude: B_eq/I times the total inertia (from the hull's GM and displacement) times
    B̂44's factor; None off roll or where the hull lacks what it needs."""
    from ..ident.derived import b44_hat_factor
    from ..ident.report import dimensional_summary

    hull, draft, axis = condition
    if hull is None or draft is None or axis != "roll":
        return None
    try:
        draft_factor = parse_draft(draft)
        factor = b44_hat_factor(hull, draft_factor)
        inertia = dimensional_summary(values, hull, axis, draft_factor).get("total_inertia_kg_m2")
    except (TankdaqError, ValueError, ZeroDivisionError):
        return None
    if factor is None or inertia is None:
        return None
    return {a: None if b is None else b * inertia * factor for a, b in b_eqs.items()}


def recording_row(path: Path, sha256: str | None = None) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """The row of one tankdaq recording and its hull's version (None when the hull is not known here).

    A file cut short (no footer), or one with corrupted chunks, is ``complete`` False: ``tankdaq
    recover`` then ``index`` makes the complete one. Raises ``RecordingError`` (one line) for a file
    that is not a readable recording.
    """
    from ..store.reader import read_recording

    recording = read_recording(path)
    meta = recording.metadata
    hull = find_hull(meta.get("hull"))
    now = utc_now()
    row: dict[str, Any] = {
        "sha256": sha256 or file_sha256(path),
        "path": str(path.resolve()),
        "size_bytes": path.stat().st_size,
        "complete": recording.complete and recording.corruption is None,  # corrupted chunks: recover too
        "recorded_utc": meta.get("release_utc") or meta.get("created_utc"),
        "hull": meta.get("hull"),
        "draft": meta.get("draft"),
        "axis": recording.axis,
        "speed_m_s": _finite(meta.get("speed_m_s")) or 0.0,
        "angle_nominal_deg": _finite(meta.get("angle_nominal_deg")),
        "release_angle_deg": _release_angle(meta, recording.events),
        **_release_instant(recording.events),
        "device_id": meta.get("device_id"),
        "firmware": meta.get("firmware"),
        "ended": ended_of(meta, recording.complete),
        "code_version": meta.get("software_version") or __version__,
        "created_utc": now,
        "updated_utc": now,
    }
    version = hull_version(hull) if hull is not None else None
    row["hull_sha256"] = version["sha256"] if version else None
    if recording.fits:
        last = recording.fits[-1]  # the final fit (or the last refit of a decay cut short)
        ci95 = {term: pair for term, pair in (last.get("ci95") or {}).items() if isinstance(pair, list)}
        warnings = json.loads(meta.get("warnings", "[]") or "[]")
        condition = (hull, row["draft"], row["axis"])
        how = FitHow(FitMethod.LIVE, settings={"fit": "the recorder's final fit, stored in the file"})
        fit = fit_fields(
            FitSource.RECORD, last["coefficients"], ci95, last.get("r2"), warnings, condition, how=how
        )
        made = {"software_version": row["code_version"], "host": meta.get("host"), "user_name": None}
        row["fit"] = fit | made | {"command": None, "created_utc": row["recorded_utc"] or now}
    return row, version


def ended_of(meta: Mapping[str, Any], complete: bool) -> str | None:
    """How a recording's decay ended (``records.DecayEnd``): ``cut`` without its footer, else its
    ``ended`` metadata, else what an older file's ``settle_reason`` says; None when it says nothing."""
    if not complete:
        return DecayEnd.CUT.value
    ended = meta.get("ended")
    try:
        found = DecayEnd(str(ended)) if ended else DecayEnd.of_settle_reason(meta.get("settle_reason"))
    except ValueError:
        found = DecayEnd.of_settle_reason(ended)
    return None if found is None else found.value


#: The files ``index`` and the hooks catalogue, by suffix: those tankdaq reads decays from
#: (``store.inputs.INPUT_FORMATS``), rows of ``decays``; but a file ``tankdaq export`` wrote (HDF5 one file
#: per decay, Parquet and MATLAB one per recording, a CSV with its ``<stem>.json`` sidecar) is a row of
#: ``exports``: its recording holds the decay.
DECAY_SUFFIXES = tuple(INPUT_FORMATS)


def export_metadata(path: Path) -> dict[str, Any] | None:
    """The metadata of a file ``tankdaq export`` wrote (HDF5 root attributes, Parquet schema metadata,
    a .mat file's ``tankdaq.meta``, a CSV's sidecar); None for another tool's file (a lab's decay). A file
    of an export's kind that cannot be read here (broken, or its library is not installed) raises
    ``RecordingError``."""
    from ..store import export_layout

    suffix = path.suffix.lower()
    reader = export_layout.METADATA_READERS.get(suffix)
    if reader is None or suffix == ".csv":
        return reader(path) if reader is not None else None
    kind, library = {  # what the file is, what reads it (and how to get it)
        ".h5": ("HDF5", "h5py"),
        ".hdf5": ("HDF5", "h5py"),
        ".parquet": ("Parquet", f"pyarrow: {install_hint('parquet')}"),
        ".mat": ("MATLAB", "scipy"),
    }[suffix]
    try:
        found = reader(path)
    except ImportError:
        raise RecordingError(f"{path}: reading a {kind} export needs {library}") from None
    except (OSError, ValueError, TypeError, KeyError) as exc:
        raise RecordingError(f"{path}: not a {kind} file tankdaq can read ({one_line(exc)})") from None
    return found


def export_row(path: Path, metadata: Mapping[str, Any], sha256: str | None = None) -> dict[str, Any]:
    """The ``exports`` row of an exported file: where it is, its hash, the recording it came from."""
    now = utc_now()
    decay = metadata.get("decay")
    source = metadata.get("source")
    return {
        "sha256": sha256 or file_sha256(path),
        "path": str(path.resolve()),
        "size_bytes": path.stat().st_size,
        "format": path.suffix.lower().lstrip("."),
        "source_path": str(Path(str(source)).resolve()) if source else None,
        "decay": int(decay) if isinstance(decay, int | float) and not isinstance(decay, bool) else None,
        "created_utc": now,
        "updated_utc": now,
    }


def lab_file_row(
    path: Path, sha256: str | None = None, axis: str | None = None
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """The row of a lab's decay file (CSV, HDF5, MATLAB, Parquet): as ``recording_row``, its condition
    from its JSON sidecar or its name (``campaign.groups.csv_labels``; unknown columns stay empty when
    neither says). ``axis``: the file's, when a command has just read its decay (with the columns the
    user named): it is not read again. Raises ``RecordingError`` for a file that holds no decay
    tankdaq can read with its default columns."""
    from ..campaign.groups import csv_labels
    from ..config.hulls import format_draft
    from ..errors import InputError
    from ..store.inputs import read_runs
    from ..store.mt_manager import file_facts

    device: dict[str, Any] = {}  # what a file says of its device (an MT Manager log's Configuration)
    if axis is None:
        try:
            runs = read_runs(path)
        except InputError as exc:
            raise RecordingError(str(exc)) from None
        if not runs:
            raise RecordingError(f"{path}: no decay in it")
        axis = runs[0].axis
        device = {key: str(runs[0].meta[key]) for key in ("device_id", "firmware") if key in runs[0].meta}
    try:
        labels = csv_labels(path)
    except InputError:  # a decay all the same: its row says where and what, the condition unknown
        labels = {}
    hull = find_hull(labels.get("hull"))
    version = hull_version(hull) if hull is not None else None
    now = utc_now()
    device = {**file_facts(path), **device}  # an MT Manager export's // block, or a log's Configuration
    row = {
        "sha256": sha256 or file_sha256(path),
        "path": str(path.resolve()),
        "size_bytes": path.stat().st_size,
        "complete": True,
        "hull": labels.get("hull"),
        "hull_sha256": version["sha256"] if version else None,
        "draft": format_draft(labels["draft"]) if "draft" in labels else None,
        "axis": labels.get("axis", axis),
        "angle_nominal_deg": _finite(labels.get("angle_deg")),
        "device_id": device.get("device_id", "")[:32] or None,
        "firmware": device.get("firmware", "")[:32] or None,
        "created_utc": now,
        "updated_utc": now,
    }
    return row, version


def decay_row(
    path: Path, sha256: str | None = None, axis: str | None = None
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """``recording_row`` or ``lab_file_row``, by the file's suffix (``axis``: ``lab_file_row``'s)."""
    if path.suffix.lower() != ".mcap":
        return lab_file_row(path, sha256, axis)
    return recording_row(path, sha256)


def worker_row(path: Path, sha256: str | None = None) -> tuple[dict[str, Any], dict[str, Any] | None] | None:
    """``decay_row`` of a file a campaign's worker has just read (``campaign.stream.FileWork``; its
    ``sha256`` from that reading), so the catalogue's writer only writes it: the row ``index`` makes of
    the file. None for an exported
    CSV (its recording holds the decay) and for a file whose row cannot be made here: the writer then
    makes it itself and says in one line why it could not."""
    try:
        if export_metadata(path) is not None:
            return None
        return decay_row(path, sha256)
    except Exception:  # the catalogue's trouble, never the campaign's
        return None


def bare_row(path: Path) -> dict[str, Any]:
    """The row of a decay file nothing can be read from yet (cut before its first data reached the
    disk): where it is, its hash, not complete. A session's log still says what it was."""
    now = utc_now()
    return {
        "sha256": file_sha256(path),
        "path": str(path.resolve()),
        "size_bytes": path.stat().st_size,
        "complete": False,
        "ended": DecayEnd.CUT.value,
        "code_version": __version__,
        "created_utc": now,
        "updated_utc": now,
    }


def _release_instant(events: list[dict[str, Any]]) -> dict[str, float | None]:
    """The first release's instant on the device clock and its 95 % half-width (None: unknown, as in a
    file written before the interval; never zero)."""
    from ..store.reader import release_u95_of

    release = next((e for e in events if e.get("kind") == EventKind.RELEASE), {})
    t_s = _finite(release.get("t_s"))
    return {"release_t_s": t_s, "release_u95_s": None if t_s is None else release_u95_of(events, t_s)}


def _release_angle(meta: Mapping[str, str], events: list[dict[str, Any]]) -> float | None:
    measured = _finite(meta.get("angle_initial_deg"))
    if measured is None:
        release = next((e for e in events if e.get("kind") == EventKind.RELEASE), {})
        measured = _finite((release.get("data") or {}).get("angle_initial_deg"))
    return None if measured is None else abs(measured)
