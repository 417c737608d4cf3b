"""What a tankdaq MCAP file holds: topics, JSON schemas, units, and the sample <-> JSON mapping.

Samples are written as JSON with a JSON schema so Foxglove (and anyone with a
JSON parser) can plot them without tankdaq; angles are in degrees there
because people read these files. Inside tankdaq everything is SI (rad).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from enum import StrEnum
from typing import Any

import numpy as np

from ..physics.terms import TERM_TABLE, equation_text
from ..samples import SAMPLE_DTYPE

TOPIC_RAW = "/xsens/raw"
TOPIC_SAMPLES = "/samples"
TOPIC_EVENTS = "/events"
TOPIC_FIT = "/fit"
TOPIC_SAMPLE_BLOCKS = "/samples/blocks"
TANKDAQ_TOPICS = (TOPIC_RAW, TOPIC_SAMPLES, TOPIC_EVENTS, TOPIC_FIT, TOPIC_SAMPLE_BLOCKS)

RUN_METADATA_NAME = "tankdaq.run"
CONFIG_ATTACHMENT_NAME = "run_config.json"
RAW_MESSAGE_ENCODING = "xbus"
BLOCK_MESSAGE_ENCODING = "tankdaq.sample-block"
#: The ``/samples/blocks`` payload: packed little-endian records, SI units (the in-memory sample layout).
BLOCK_DTYPE = SAMPLE_DTYPE.newbyteorder("<")


class EventKind(StrEnum):
    """What a recording's event says happened (``/tankdaq/events``)."""

    RELEASE = "release"
    SETTLED = "settled"
    GAP = "gap"
    WARNING = "warning"
    UNPLUG = "unplug"
    NOTE = "note"


#: The kinds as plain text (the events' JSON schema and the channel's metadata).
EVENT_KINDS = tuple(kind.value for kind in EventKind)

#: JSON field -> (sample field, factor from SI to the file's unit, unit). Order is the file's field order.
SAMPLE_FIELDS: dict[str, tuple[str, float, str]] = {
    "t_s": ("t", 1.0, "s (device clock)"),
    "ticks": ("ticks", 1.0, "0.1 ms (unwrapped SampleTimeFine)"),
    "counter": ("counter", 1.0, "- (PacketCounter, wraps at 65536)"),
    "roll_deg": ("roll", np.degrees(1.0), "deg"),
    "pitch_deg": ("pitch", np.degrees(1.0), "deg"),
    "yaw_deg": ("yaw", np.degrees(1.0), "deg"),
    "roll_rate_deg_s": ("p", np.degrees(1.0), "deg/s"),
    "pitch_rate_deg_s": ("q", np.degrees(1.0), "deg/s"),
    "yaw_rate_deg_s": ("r", np.degrees(1.0), "deg/s"),
    "acc_x_m_s2": ("ax", 1.0, "m/s^2"),
    "acc_y_m_s2": ("ay", 1.0, "m/s^2"),
    "acc_z_m_s2": ("az", 1.0, "m/s^2"),
    "status": ("status", 1.0, "bits (StatusWord)"),
}
_INTEGER_FIELDS = ("ticks", "counter", "status")
_FORMATS = {name: "d" if name in _INTEGER_FIELDS else "r" for name in SAMPLE_FIELDS}

SAMPLE_FRAME = "sensor frame of the MTi-G (Xsens ENU: x forward, y left, z up); Euler angles roll-pitch-yaw"


def _schema(title: str, properties: dict[str, Any], required: Sequence[str]) -> bytes:
    body = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": properties,
        "required": list(required),
    }
    return json.dumps(body, indent=1).encode()


def _number(unit: str, description: str = "") -> dict[str, Any]:
    """A number field, null when missing; typed "number" only, as Foxglove's parser takes one type name."""
    return {"type": "number", "description": f"{description} ({unit}; null when missing)".strip()}


def _per_term(item: dict[str, Any], description: str) -> dict[str, Any]:
    """An object with one optional property per term of the term table (Foxglove needs named properties
    to plot): the nine of the equation and the extra effects (``fc``) a live model may hold."""
    return {"type": "object", "description": description, "properties": {term: item for term in TERM_TABLE}}


SAMPLES_SCHEMA = _schema(
    "tankdaq.Sample",
    {
        name: (
            {"type": "integer", "description": unit}
            if name in _INTEGER_FIELDS
            else _number(unit, name.split("_")[0])
        )
        for name, (_, _, unit) in SAMPLE_FIELDS.items()
    },
    list(SAMPLE_FIELDS),
)

EVENTS_SCHEMA = _schema(
    "tankdaq.Event",
    {
        "t_s": _number("s", "device time of the event"),
        "kind": {"type": "string", "enum": list(EVENT_KINDS)},
        "message": {"type": "string"},
        "data": {"type": "object", "description": "kind-specific details", "properties": {}},
    },
    ["t_s", "kind", "message"],
)

FIT_SCHEMA = _schema(
    "tankdaq.Fit",
    {
        "t_s": _number("s", "device time of the fit"),
        "terms": {"type": "array", "items": {"type": "string", "enum": list(TERM_TABLE)}},
        "coefficients": _per_term({"type": "number"}, "fitted value per term (units in channel metadata)"),
        "std": _per_term({"type": "number"}, "standard error per term"),
        "ci95": _per_term(
            {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
            "95 % confidence interval [low, high] per term",
        ),
        "r2": _number("-", "coefficient of determination of the angle"),
    },
    ["t_s", "terms", "coefficients"],
)

CHANNEL_METADATA: dict[str, dict[str, str]] = {
    TOPIC_RAW: {
        "content": "serial bytes exactly as received from the device (Xbus frames, unparsed)",
        "log_time": "host arrival, ns since epoch",
    },
    TOPIC_SAMPLES: {
        "units": json.dumps({name: unit for name, (_, _, unit) in SAMPLE_FIELDS.items()}),
        "frame": SAMPLE_FRAME,
        "log_time": "host arrival of the sample, ns since epoch",
    },
    TOPIC_SAMPLE_BLOCKS: {
        "content": (
            f"the {TOPIC_SAMPLES} messages written since the previous block, as packed little-endian "
            "records in SI units (rad, rad/s); host_t is the log time of each sample's message; "
            f"non-finite values are NaN (null in {TOPIC_SAMPLES})"
        ),
        "dtype": json.dumps([[name, BLOCK_DTYPE[name].str] for name in BLOCK_DTYPE.names or ()]),
        "log_time": "host arrival of the block's first sample, ns since epoch",
    },
    TOPIC_EVENTS: {"kinds": ",".join(EVENT_KINDS), "t_s": "device time, s"},
    TOPIC_FIT: {
        "equation": equation_text(),
        "angle_unit": "rad (coefficients per unit total inertia)",
        "term_units": json.dumps({name: spec.unit for name, spec in TERM_TABLE.items()}),
    },
}

#: What the ``tankdaq.run`` metadata record holds (ITTC 7.5-02-07-04.5 §6, as far as the daemon can know).
RUN_METADATA_KEYS: dict[str, str] = {
    "hull": "model id (hull configuration name)",
    "hull_description": "the hull configuration's description",
    "hull_<dimension>": "main dimensions from the hull configuration, e.g. hull_length_m, hull_beam_m",
    "draft": "loading condition as a factor of the design draft, e.g. 1.1T",
    "axis": "decay axis: roll or pitch",
    "angle_nominal_deg": "the release angle the engineer aimed for",
    "angle_initial_deg": "measured angle at release (written at close)",
    "release_t_s": "device time of the release (written at close)",
    "release_utc": "wall-clock time of the release (written at close)",
    "sample_rate_hz": "configured output rate; measured_sample_rate_hz is written at close",
    "device_id": "Xsens device id",
    "product_code": "Xsens product code",
    "firmware": "device firmware revision",
    "baud": "serial line rate the device streamed at (bit/s)",
    "baud_changed": "true when tankdaq moved the device to that rate (baud_before: the rate it was at)",
    "orientation_source": "where roll and pitch come from: Euler angles, quaternion, rotation matrix "
    "(the first output the device accepted) or integrated rate of turn (an IMU-class device)",
    "orientation_refused": "the orientation outputs the device refused, with its error codes (absent: none)",
    "gyro_bias_<p|q>_rad_s": "integrated rate of turn: the gyro bias learnt (written at close; replay "
    "starts from it)",
    "link_<counter>": "serial link counters at close: bytes, frames, bad_checksums, skipped_bytes, "
    "false_syncs (false frames turned away), gaps, lost",
    "software_version": "tankdaq version that wrote the file",
    "operator": "who ran the test",
    "sim_seed": "the built-in simulator's seed (absent: a real device); --seed with it plays the same test",
    "note": "free text",
    "speed_m_s": "carriage speed during the decay (a speed channel's mean; tankdaq import)",
    "source_file": "tankdaq import: the file the decay was read from",
    "source_sha256": "tankdaq import: the SHA-256 of that file's bytes",
    "source_format": "tankdaq import: its format (MT Manager log, LabVIEW TDMS, CSV, ...)",
    "source_decay": "tankdaq import: which decay of the file (1..), in the order they were found",
    "source_header": "tankdaq import: what the reader read from the file's header (JSON)",
    "conversions": "tankdaq import: what the reading and the import decided, one line each (JSON)",
    "warnings": "JSON list of warnings raised during the run (written at close)",
    "created_utc": "when the file was started",
    "closed_utc": "when the file was finished (absent in a file whose writer was killed)",
}


def metadata_strings(values: Mapping[str, object]) -> dict[str, str]:
    """MCAP metadata values must be strings: numbers keep full precision, containers become JSON."""
    out: dict[str, str] = {}
    for key, value in values.items():
        if value is None:
            continue
        if isinstance(value, str):
            out[key] = value
        elif isinstance(value, bool):
            out[key] = "true" if value else "false"
        elif isinstance(value, int | float | np.integer | np.floating):
            out[key] = repr(float(value)) if isinstance(value, float | np.floating) else str(int(value))
        else:
            out[key] = json.dumps(value, default=float)
    return out


def samples_to_json(samples: np.ndarray) -> list[bytes]:
    """One JSON object per sample, built column-wise (no per-sample dict or json.dumps).

    Floats are written with repr, so converting back to rad recovers the value to
    the last bit of the degree conversion; NaN and infinities become null.
    """
    columns: list[list[Any]] = []
    has_gaps = False
    for name, (field, factor, _) in SAMPLE_FIELDS.items():
        values = samples[field]
        if name in _INTEGER_FIELDS:
            columns.append(values.astype(np.int64).tolist())
            continue
        scaled = values * factor if factor != 1.0 else values.astype(np.float64)
        finite = np.isfinite(scaled)
        if not finite.all():
            has_gaps = True
            scaled = np.where(finite, scaled, np.nan)
        columns.append(scaled.tolist())
    template = "{" + ",".join(f'"{name}":%{_FORMATS[name]}' for name in SAMPLE_FIELDS) + "}"
    texts = [template % row for row in zip(*columns, strict=True)]
    if has_gaps:
        texts = [text.replace("nan", "null") for text in texts]
    return [text.encode() for text in texts]


def sample_block(samples: np.ndarray, host_ns: np.ndarray) -> bytes:
    """The ``/samples/blocks`` payload for samples whose messages are stamped ``host_ns``.

    Holds bit for bit what reading the per-sample messages gives back (the degree
    round trip, host_t from the stamps, non-finite as NaN), so a file reads the same
    whichever of the two a reader takes.
    """
    block = samples.astype(BLOCK_DTYPE)
    block["host_t"] = host_ns / 1e9
    for name, (field, factor, _) in SAMPLE_FIELDS.items():
        if name not in _INTEGER_FIELDS:
            values = block[field] * factor / factor if factor != 1.0 else block[field]
            block[field] = np.where(np.isfinite(values), values, np.nan)
    return block.tobytes()


def samples_from_blocks(payloads: Sequence[bytes]) -> np.ndarray:
    """SAMPLE_DTYPE array from ``/samples/blocks`` messages, in order."""
    blocks = [np.frombuffer(payload, dtype=BLOCK_DTYPE) for payload in payloads]
    if not blocks:
        return np.zeros(0, dtype=SAMPLE_DTYPE)
    return np.concatenate(blocks).astype(SAMPLE_DTYPE)


def samples_from_json(payloads: Sequence[bytes], host_ns: Sequence[int] | None = None) -> np.ndarray:
    """SAMPLE_DTYPE array from ``/samples`` messages (degrees back to rad; null back to NaN)."""
    out = np.zeros(len(payloads), dtype=SAMPLE_DTYPE)
    if not payloads:
        return out
    rows = json.loads(b"[" + b",".join(payloads) + b"]")
    for name, (field, factor, _) in SAMPLE_FIELDS.items():
        if name in _INTEGER_FIELDS:
            out[field] = [row.get(name, 0) for row in rows]
        else:
            column = np.array([row.get(name) for row in rows], dtype=float)
            out[field] = column / factor if factor != 1.0 else column
    if host_ns is not None:
        out["host_t"] = np.asarray(host_ns, dtype=np.int64) / 1e9
    return out


def interval_pairs(
    coefficients: Mapping[str, float], ci95: Mapping[str, object] | None
) -> dict[str, list[float]]:
    """ci95 as ``{term: [low, high]}``; a single number per term is read as the half-width."""
    pairs: dict[str, list[float]] = {}
    for term, value in (ci95 or {}).items():
        bounds = np.asarray(value, dtype=float)
        if bounds.ndim == 0:
            centre, half = float(coefficients[term]), float(bounds)
            pairs[term] = [centre - half, centre + half]
        else:
            low, high = (float(v) for v in bounds)
            pairs[term] = [low, high]
    return pairs


def fit_record(
    t_s: float,
    coefficients: Mapping[str, float],
    std: Mapping[str, float] | None = None,
    ci95: Mapping[str, object] | None = None,
    r2: float | None = None,
    extra: Mapping[str, object] | None = None,
) -> dict[str, Any]:
    """The ``/fit`` message for one set of coefficients (terms in canonical order)."""
    unknown = sorted(set(coefficients) - set(TERM_TABLE))
    if unknown:
        raise ValueError(f"unknown decay terms {unknown}; known: {', '.join(TERM_TABLE)}")
    terms = [term for term in TERM_TABLE if term in coefficients]
    record: dict[str, Any] = {
        "t_s": float(t_s),
        "terms": terms,
        "coefficients": {term: float(coefficients[term]) for term in terms},
        "std": {term: float(v) for term, v in (std or {}).items()},
        "ci95": interval_pairs(coefficients, ci95),
        "r2": None if r2 is None else float(r2),
    }
    for key, value in (extra or {}).items():
        record.setdefault(key, value)
    return record
