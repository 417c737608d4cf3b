"""``tankdaq.read``: a recording (MCAP) or a decay file (CSV, HDF5, MATLAB, Parquet) as pandas DataFrames
with units in the column names.

The library keeps SI units and radians inside (``samples.SAMPLE_DTYPE``, ``records.DecayRun``); this is an
edge, so angles and rates come out in degrees and every column name ends in its unit (``roll_deg``,
``p_deg_s``, ``az_m_s2``): the names of ``tankdaq export``'s files (``store.export_layout``: the sample
field and the suffix of its unit), with degrees for radians, so a DataFrame and an exported file speak one
vocabulary. ``time_s`` counts from the first release (the time people plot a decay against);
``device_time_s`` keeps the device clock beside it.
"""

from __future__ import annotations

import html
import itertools
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from ..config import validation
from ..errors import InputError
from ..records import DecayRun
from ..samples import AXIS_FIELDS, SAMPLE_UNITS
from ..store.export_layout import DEVICE_TIME_COLUMN, TIME_COLUMN, column_name
from . import arguments

if TYPE_CHECKING:
    import pandas as pd

    from ..store.csv_import import CsvOptions

#: SI unit -> (the unit people read, its column suffix): angles and rates in degrees at this edge.
DEGREES = {"rad": ("deg", "deg"), "rad/s": ("deg/s", "deg_s")}


class RecordingMeta(TypedDict, total=False):
    """What is known about a recording, typed (a recording's metadata is stored as text)."""

    source: str  # the file read
    format: str  # "tankdaq recording" or "CSV"
    axis: str  # roll or pitch
    hull: str | None
    draft: float  # factor of the design draft
    angle_nominal_deg: float
    angle_initial_deg: float
    sample_rate_hz: float
    device_id: str
    product_code: str  # a text export's header (an MT Manager export's // block), as written
    firmware: str  # the export's header or an MT Manager log's Configuration message
    filter_profile: str | int  # an export's header says it as text, a log's Configuration as a number
    mt_manager_version: str
    source_format: str
    update_rate_hz: float
    log_date: str  # when an MT Manager log was started, as it says it (YYYYMMDD, HHMMSSss)
    log_time: str
    speed_m_s: float  # the first decay's carriage speed (a --speed-col)
    operator: str
    note: str
    release_device_time_s: list[float]  # each decay's release on the device clock
    release_u95_s: list[float | None]  # the half-width of each release's 95 % interval (None: unknown)
    complete_file: bool  # False: the file was cut short (``truncation`` says what to do)
    truncation: str | None
    stored: dict[str, object]  # a recording's metadata as written, every key, typed


def people_column(field_name: str, values: np.ndarray) -> tuple[str, str, np.ndarray]:
    """(column name, unit, values) of one sample field at the edge: the export's name
    (``store.export_layout``: the field and its unit's suffix, the device clock ``device_time_s``) with
    angles and rates in degrees (``roll_deg``, ``p_deg_s``)."""
    if field_name == "t":
        return DEVICE_TIME_COLUMN, "s", np.asarray(values, dtype=float)
    unit = SAMPLE_UNITS[field_name]
    if unit in DEGREES:
        shown, suffix = DEGREES[unit]
        return f"{field_name}_{suffix}", shown, np.degrees(np.asarray(values, dtype=float))
    return column_name(field_name), unit, np.asarray(values)


def units_frame(columns: dict[str, tuple[str, np.ndarray]]) -> pd.DataFrame:
    """A DataFrame of ``{name: (unit, values)}``; ``df.attrs["units"]`` maps each column to its unit."""
    import pandas as pd

    table = pd.DataFrame({name: values for name, (_unit, values) in columns.items()})
    table.attrs["units"] = {name: unit for name, (unit, _values) in columns.items()}
    return table


def _release_of(run: DecayRun) -> float:
    """Where a decay's own time starts: its release on the file's clock (a recording's release event; an
    exported CSV's last ``release_t_s`` at or before the run; else its first sample, the release found)."""
    value = run.meta.get("release_t_s")
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, list):
        before = [float(r) for r in value if isinstance(r, int | float) and r <= run.t[0]]
        return max(before) if before else float(run.t[0])
    return float(run.t[0])


def _release_u95(run: DecayRun) -> float | None:
    value = run.meta.get("release_u95_s")
    return float(value) if isinstance(value, int | float) else None


@dataclass(frozen=True, eq=False)  # holds DataFrames or fits: compared by identity
class Decay:
    """One free decay of a recording: from its release to the next release (or the file's end).

    ``samples`` has ``time_s`` from the release, the angle and rate in degrees, and the other channels the
    file holds; ``run`` is the same decay as the estimators see it (SI, rad), which ``tankdaq.identify``
    accepts too.
    """

    number: int
    run: DecayRun
    samples: pd.DataFrame

    @property
    def name(self) -> str:
        return self.run.name

    @property
    def initial_angle_deg(self) -> float:
        return float(np.degrees(self.run.angle[0]))

    @property
    def duration_s(self) -> float:
        return self.run.duration

    @property
    def release_u95_s(self) -> float | None:
        """Half-width (s) of the 95 % interval of the release instant; None: unknown (a file written before
        the interval, a lab's CSV), never zero."""
        return _release_u95(self.run)


def decay_frame(run: DecayRun) -> pd.DataFrame:
    """A decay's samples at the edge: ``time_s`` from its release, the angle and rate in degrees
    (``roll_deg``, ``p_deg_s``), and its channels (``_channel_column``)."""
    angle_field, rate_field = AXIS_FIELDS[run.axis]
    name, unit, angle = people_column(angle_field, run.angle)
    columns: dict[str, tuple[str, np.ndarray]] = {
        TIME_COLUMN: ("s", run.t - _release_of(run)),
        name: (unit, angle),
    }
    if run.rate is not None:
        name, unit, rate = people_column(rate_field, run.rate)
        columns[name] = (unit, rate)
    for channel, values in run.channels.items():
        name, unit, shown = _channel_column(channel, values)
        columns[name] = (unit, shown)
    return units_frame(columns)


#: The SI suffixes a CSV reader leaves on a channel's name (``_deg``/``_rad`` columns lose theirs).
_KEPT_SUFFIXES = ("_rad_s", "_m_s2")


def _channel_column(channel: str, values: np.ndarray) -> tuple[str, str, np.ndarray]:
    """A CSV channel at the edge: a sample field (an exported file's ``pitch_rad``, ``q_rad_s``, ``ax_m_s2``)
    under the samples' name and unit; any other column as the reader gave it (``as read``: SI when its
    name said a unit, else the file's own)."""
    field_name = next((channel[: -len(s)] for s in _KEPT_SUFFIXES if channel.endswith(s)), channel)
    if field_name in SAMPLE_UNITS and field_name != "t":
        return people_column(field_name, values)
    return channel, "s" if channel == DEVICE_TIME_COLUMN else "as read", values


@dataclass(frozen=True, eq=False)  # holds DataFrames or fits: compared by identity
class Recording:
    """A recording or decay file read for people: ``samples`` (a DataFrame, units in the column names,
    ``time_s`` from the first release), ``meta`` (typed), ``decays`` (one ``Decay`` per release) and the
    lines the reading has for the user (``notices``). Shown as a table in a notebook.

    >>> rec = tankdaq.read("recordings/demo/swath_T_roll_8deg_20261121-143015_run01.mcap")  # doctest: +SKIP
    >>> rec.samples[["time_s", "roll_deg", "p_deg_s"]].head()  # doctest: +SKIP
    """

    path: Path
    samples: pd.DataFrame
    meta: RecordingMeta
    decays: list[Decay]
    notices: list[str] = field(default_factory=list)

    @property
    def units(self) -> dict[str, str]:
        """Each column of ``samples`` and its unit."""
        return dict(self.samples.attrs.get("units", {}))

    def export(
        self, file_format: str, out_dir: str | Path | None = None, frame: str = "release"
    ) -> list[Path]:
        """Write this recording as ``tankdaq export`` does (``store.export``: ``csv`` with its ``.json``
        sidecar, ``h5`` one file per decay, ``parquet``, ``mat``) into ``out_dir`` (default: beside it);
        returns the files written. The files hold the recording's SI values exactly; ``frame`` is the
        time origin, ``"release"`` (time since the release) or ``"device"``."""
        from ..store.export import FRAMES, WRITERS, export_recording
        from ..store.inputs import RECORDING_FORMAT

        file_format = arguments.text(file_format, "file_format", choices=tuple(WRITERS))
        folder = arguments.optional_path(out_dir, "out_dir", "a folder (str or pathlib.Path) or None")
        frame = arguments.text(frame, "frame", choices=FRAMES)
        if self.meta.get("format") != RECORDING_FORMAT:
            raise InputError(f"{self.path} is a CSV file already: only a recording (.mcap) is exported")
        return export_recording(self.path, file_format, folder, frame)

    def to_csv(self, out_dir: str | Path | None = None, frame: str = "release") -> Path:
        """The CSV ``pd.read_csv`` reads without options (units in the column names, the metadata in a
        ``.json`` sidecar beside it); returns its path.

        >>> pd.read_csv(rec.to_csv("exports"))  # doctest: +SKIP
        """
        return self.export("csv", out_dir, frame)[0]

    def to_hdf5(self, out_dir: str | Path | None = None, frame: str = "release") -> list[Path]:
        """One HDF5 file per decay (a dataset per column with its ``unit`` attribute, the metadata as typed
        root attributes); returns their paths.

        >>> h5py.File(rec.to_hdf5("exports")[0])["roll_rad"][:]  # doctest: +SKIP
        """
        return self.export("h5", out_dir, frame)

    def _repr_html_(self) -> str:
        meta = {k: v for k, v in self.meta.items() if k != "stored"}
        rows = "".join(
            f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in meta.items()
        )
        decays = "".join(
            f"<tr><td>{d.number}</td><td>{html.escape(d.name)}</td><td>{d.initial_angle_deg:.2f}</td>"
            f"<td>{d.duration_s:.2f}</td><td>{d.run.t.size}</td></tr>"
            for d in self.decays
        )
        notices = "".join(f"<li>{html.escape(line)}</li>" for line in self.notices)
        return (
            f"<h4>{html.escape(self.path.name)}</h4><table>{rows}</table>"
            "<table><tr><th>decay</th><th>name</th><th>initial angle (deg)</th><th>duration (s)</th>"
            f"<th>samples</th></tr>{decays}</table>"
            + (f"<ul>{notices}</ul>" if notices else "")
            + self.samples.head().to_html(index=False)
        )


def read(
    path: str | Path,
    *,
    axis: str | None = None,
    time_col: str = "time_s",
    angle_col: str = "angle_deg",
    rate_col: str | None = "rate_deg_s",
    angle_unit: str | None = None,
    time_unit: str | None = None,
    sample_rate_hz: float | None = None,
    device: str | None = None,
    speed_col: str | None = None,
) -> Recording:
    """Read a tankdaq recording (``.mcap``) or a decay file (a CSV in any spreadsheet dialect, an MT Manager
    text export, HDF5, MATLAB, Parquet, LabVIEW TDMS, an MT Manager ``.mtb`` log; the column settings are
    ``tankdaq identify``'s) into a ``Recording``; its decays are found as ``identify`` finds them.
    ``sample_rate_hz``: the sample rate of a text export that does not say it (``--rate``); ``device``: the
    device of a log that holds several (its id in hex, or its bus id); ``speed_col``: a carriage-speed
    column (each decay's ``speed_m_s``).

    >>> rec = tankdaq.read("run.mcap")  # doctest: +SKIP
    >>> rec.decays[0].samples.plot(x="time_s", y="roll_deg")  # doctest: +SKIP
    """
    from ..store.csv_import import CsvOptions
    from ..store.inputs import input_format

    path = arguments.path(path, "path", "a recording or decay file's path (str or pathlib.Path)")
    axis, time_col, angle_col, rate_col, angle_unit, time_unit = columns_given(
        axis, time_col, angle_col, rate_col, angle_unit, time_unit
    )
    kind = input_format(path).name  # an unknown suffix is one line before anything is read
    rate_hz = arguments.optional_number(sample_rate_hz, "sample_rate_hz", 0.1, 100_000, "Hz")
    device = arguments.optional_text(device, "device", "a device id (hex) or bus id, or None")
    speed_col = arguments.optional_text(speed_col, "speed_col", "a column name or None")
    options = CsvOptions(
        time_col, angle_col, rate_col, angle_unit, False, time_unit, rate_hz, device, speed_col
    )
    if path.suffix.lower() == ".mcap":
        return _read_recording(path, axis, kind)
    return _read_columns(path, axis, options, kind)


def columns_given(
    axis: object,
    time_col: object,
    angle_col: object,
    rate_col: object,
    angle_unit: object,
    time_unit: object,
) -> tuple[str | None, str, str, str | None, str | None, str | None]:
    """The reading settings ``read`` and ``Reading`` take, checked by name (``api.arguments``)."""
    from ..store.csv_units import ANGLE_UNITS, TIME_UNITS

    axis = arguments.optional_text(axis, "axis", "roll, pitch or None")
    return (
        None if axis is None else validation.decay_axis(axis, option="axis"),
        arguments.text(time_col, "time_col", "a column name"),
        arguments.text(angle_col, "angle_col", "a column name"),
        arguments.optional_text(rate_col, "rate_col", "a column name or None"),
        arguments.optional_text(angle_unit, "angle_unit", choices=tuple(ANGLE_UNITS)),
        arguments.optional_text(time_unit, "time_unit", choices=tuple(TIME_UNITS)),
    )


def _meta(path: Path, kind: str, axis: str, runs: list[DecayRun]) -> RecordingMeta:
    """What is known about a file: its decays' metadata (typed by the readers) and their releases."""
    meta: RecordingMeta = {"source": str(path), "format": kind, "axis": runs[0].axis if runs else axis}
    for key in RecordingMeta.__annotations__:
        if runs and key in runs[0].meta and key not in ("source", "axis", "format"):
            meta[key] = runs[0].meta[key]  # type: ignore[literal-required]
    meta["release_device_time_s"] = [_release_of(run) for run in runs]
    meta["release_u95_s"] = [_release_u95(run) for run in runs]
    return meta


def _read_recording(path: Path, axis: str | None, kind: str) -> Recording:
    """A recording: every sample, and one decay per release event (a recording stopped before any
    release has its samples and no decay, and says so)."""
    from ..ident.inputs import input_notices, read_decays
    from ..store.export import typed_metadata
    from ..store.reader import read_recording
    from ..store.schemas import EventKind

    recording = read_recording(path)
    released = any(event.get("kind") == EventKind.RELEASE for event in recording.events)
    runs = read_decays(path, axis) if released else []
    meta = _meta(path, kind, axis or recording.axis, runs)
    meta["stored"] = typed_metadata(recording.metadata)
    samples = _recording_samples(recording.samples, meta["release_device_time_s"])
    decays = [Decay(n, run, part) for n, (run, part) in enumerate(
        zip(runs, _split_at(samples, meta["release_device_time_s"]), strict=True), start=1
    )]  # fmt: skip
    notices = input_notices(runs)
    if not released:
        notices.append(f"{path.name}: no release recorded (stopped before one was detected): no decay")
    return Recording(path, samples, meta, decays, notices)


def _read_columns(path: Path, axis: str | None, options: CsvOptions, kind: str) -> Recording:
    """A decay file of columns (CSV, HDF5, MATLAB, Parquet): the record whole, and its decays as
    ``identify`` finds them."""
    from dataclasses import replace

    from ..ident.inputs import input_notices, read_decays
    from ..store.inputs import read_runs

    o = options
    wholes = read_runs(path, axis, replace(options, keep_all=True))
    if len(wholes) > 1:  # a log of several devices: one Recording is one device's
        names = ", ".join(str(run.meta.get("device_id", run.meta.get("bus_id"))) for run in wholes)
        raise InputError(f"{path} holds {len(wholes)} devices ({names}): choose one with device=")
    (whole,) = wholes
    runs = read_decays(path, axis, o.time_col, o.angle_col, o.rate_col, o.angle_unit, False, 0, o.time_unit,
                       o.sample_rate_hz, device=o.device, speed_col=o.speed_col)  # fmt: skip
    meta = _meta(path, kind, runs[0].axis, runs)
    samples = decay_frame(whole)
    samples[TIME_COLUMN] -= meta["release_device_time_s"][0] - float(whole.t[0])
    decays = [Decay(n, run, decay_frame(run)) for n, run in enumerate(runs, start=1)]
    return Recording(path, samples, meta, decays, input_notices(runs))


def _split_at(samples: pd.DataFrame, releases: list[float]) -> list[pd.DataFrame]:
    """A recording's samples from each release to the next, ``time_s`` from that release."""
    device_time = samples["device_time_s"].to_numpy()
    parts = []
    for start, stop in itertools.pairwise([*releases, np.inf]):
        part = samples[(device_time >= start) & (device_time < stop)].reset_index(drop=True)
        part["time_s"] = part["device_time_s"] - start
        part.attrs["units"] = dict(samples.attrs["units"])
        parts.append(part)
    return parts


def _recording_samples(samples: np.ndarray, releases: list[float]) -> pd.DataFrame:
    """Every sample of a recording at the edge, ``time_s`` from the first release."""
    origin = releases[0] if releases else float(samples["t"][0])
    columns: dict[str, tuple[str, np.ndarray]] = {TIME_COLUMN: ("s", samples["t"] - origin)}
    for name in samples.dtype.names or ():
        column, unit, values = people_column(name, samples[name])
        columns[column] = (unit, values)
    return units_frame(columns)


#: What ``identify``, ``compare_models`` and ``diagnose`` take as their decays, as the refusing line says it.
SOURCES = (
    "a path, a Recording, a Decay or a DecayRun (tankdaq.read gives them), a DataFrame of a decay, "
    "or a list of them"
)


def sources_given(value: object, name: str = "sources") -> list[Any]:
    """The decays given to a fit, checked (``api.arguments``): a path (str or ``Path``), a decay read
    (``Recording``, ``Decay``, ``DecayRun``) or a DataFrame of one (``frame_runs``: its decays found
    here), or a non-empty list of them."""
    read_ones = (Recording, Decay, DecayRun)
    one = isinstance(value, str | os.PathLike | Recording | Decay | DecayRun) or _is_frame(value)
    items = [value] if one else arguments.several(value, name, SOURCES)
    given: list[Any] = []
    for number, item in enumerate(items, start=1):
        if _is_frame(item):
            given += frame_runs(item, f"{name} DataFrame {number}" if len(items) > 1 else f"{name} DataFrame")
        else:
            given.append(item if isinstance(item, read_ones) else arguments.path(item, name, SOURCES))
    return given


#: A DataFrame's angle column (deg) as ``identify`` takes it, and the axis its name says (None: roll).
FRAME_ANGLES: dict[str, str | None] = {"angle_deg": None, "roll_deg": "roll", "pitch_deg": "pitch"}
#: Its rate column (deg/s), when it has one.
FRAME_RATES = ("rate_deg_s", "p_deg_s", "q_deg_s")


def _is_frame(value: object) -> bool:
    """Whether ``value`` is a DataFrame, without importing pandas (0.4 s) for a path: a DataFrame can
    exist only where pandas was imported already."""
    pandas = sys.modules.get("pandas")
    return pandas is not None and isinstance(value, pandas.DataFrame)


def frame_runs(table: pd.DataFrame, name: str) -> list[DecayRun]:
    """The decays of a DataFrame, found as in a CSV of its columns: ``time_s`` (s, from any origin) and
    the angle in degrees (``angle_deg``, or ``roll_deg``/``pitch_deg`` as ``tankdaq.read`` names them),
    the rate (``rate_deg_s``, ``p_deg_s``, ``q_deg_s``) when it is there; other numeric columns are kept
    as channels. A ``Recording``'s ``samples`` or a ``Decay``'s are such tables."""
    from pandas.api.types import is_numeric_dtype

    from ..ident.inputs import found_decays
    from ..store.csv_import import ColumnData, CsvOptions, runs_of_columns

    angle = next((column for column in FRAME_ANGLES if column in table.columns), None)
    if TIME_COLUMN not in table.columns or angle is None:
        has = ", ".join(map(str, list(table.columns)[:8])) or "no columns"
        raise InputError(
            f"{name}: give a DataFrame with columns time_s (s) and angle_deg, roll_deg or pitch_deg (deg), "
            f"or a file; this one has {has}"
        )
    rate = next((column for column in FRAME_RATES if column in table.columns), None)
    columns = {str(c): table[c].to_numpy(dtype=float) for c in table.columns if is_numeric_dtype(table[c])}
    options = CsvOptions(TIME_COLUMN, angle, rate, "deg", False, "s")
    return found_decays(
        runs_of_columns(Path(name), ColumnData(columns, {}, {}), options, FRAME_ANGLES[angle])
    )


def runs_of(data: Any) -> list[DecayRun] | None:
    """The decays of an object ``tankdaq.identify`` accepts in place of a path (a ``Recording``, a
    ``Decay``, a ``DecayRun``); None for a path."""
    if isinstance(data, Recording):
        return [decay.run for decay in data.decays]
    if isinstance(data, Decay):
        return [data.run]
    if isinstance(data, DecayRun):
        return [data]
    return None
