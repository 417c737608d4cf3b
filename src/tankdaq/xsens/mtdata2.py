"""MTData2 (MID 0x36): the data-identifier table, value codecs and the per-message decoder.

The table and codecs are everyone's (the live decoder's ``layouts``, the simulator's encoder); the
per-message decoder ``decode_mtdata2`` is a reference decoder: the live path decodes whole captures in
columns (``column_decoder``), and the tests hold it to this one's values.

A payload is a run of ``XDI (u16) | SIZE (u8) | DATA``. The XDI's low nibble carries the
precision (bits 1-0) and, for orientation and velocity, the coordinate frame (bits 3-2);
dispatch is on ``xdi & 0xFFF0``. Values stay in device units (Euler angles in degrees):
conversion to SI happens once, when messages become samples (``column_decoder.to_samples``).
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import astuple, dataclass, fields
from datetime import UTC, datetime
from typing import Any

from ..errors import ProtocolError
from .constants import DataKind

TYPE_MASK = 0xFFF0
PRECISION_MASK = 0x0003
FRAME_MASK = 0x000C

#: Precision name -> format bits (LLCP Table 17).
PRECISIONS: dict[str, int] = {"float32": 0x0, "fp1220": 0x1, "fp1632": 0x2, "float64": 0x3}
PRECISION_NAMES: dict[int, str] = {bits: name for name, bits in PRECISIONS.items()}
#: Bytes per real value for each precision's format bits.
REAL_SIZES: dict[int, int] = {0x0: 4, 0x1: 4, 0x2: 6, 0x3: 8}
#: Coordinate frame name -> format bits (orientation and velocity outputs only).
FRAMES: dict[str, int] = {"ENU": 0x0, "NED": 0x4, "NWU": 0x8}
FRAME_NAMES: dict[int, str] = {bits: name for name, bits in FRAMES.items()}

FP1220_SCALE = 1 << 20
FP1632_SCALE = 1 << 32


@dataclass(frozen=True)
class UtcTime:
    """UtcTime output: calendar time with nanoseconds and the validity flags (bit 2 = UTC usable)."""

    ns: int
    year: int
    month: int
    day: int
    hour: int
    minute: int
    second: int
    flags: int

    @property
    def valid(self) -> bool:
        """True when the fields form a real UTC instant (before a GNSS fix a device sends zeros).

        A leap second (second 60) is a valid UTC instant; the flags are the device's own verdict.
        """
        if not (1 <= self.year <= 9999 and 0 <= self.ns < 1_000_000_000):
            return False
        if not (0 <= self.hour < 24 and 0 <= self.minute < 60 and 0 <= self.second <= 60):
            return False
        try:
            datetime(self.year, self.month, self.day, tzinfo=UTC)
        except ValueError:
            return False
        return True

    def isoformat(self) -> str | None:
        """RFC 3339 text with trailing zeros of the fraction dropped ('2019-01-20T13:47:24.1219Z');
        None when the fields are not a time (``valid`` is False): kept as invalid, never an error."""
        if not self.valid:
            return None
        fraction = f"{self.ns:09d}".rstrip("0")
        return (
            f"{self.year:04d}-{self.month:02d}-{self.day:02d}T{self.hour:02d}:{self.minute:02d}:"
            f"{self.second:02d}" + (f".{fraction}" if fraction else "") + "Z"
        )


@dataclass(frozen=True)
class GnssPvt:
    """GnssPvtData output (LLCP Table 25), u-blox NAV-PVT-like, in device units (1e-7 deg, mm, mm/s, 0.01)."""

    itow: int
    year: int
    month: int
    day: int
    hour: int
    minute: int
    second: int
    valid: int
    t_acc: int
    nano: int
    fix_type: int
    flags: int
    num_sv: int
    reserved1: int
    lon: int
    lat: int
    height: int
    h_msl: int
    h_acc: int
    v_acc: int
    vel_n: int
    vel_e: int
    vel_d: int
    g_speed: int
    head_mot: int
    s_acc: int
    head_acc: int
    head_veh: int
    gdop: int
    pdop: int
    tdop: int
    vdop: int
    hdop: int
    ndop: int
    edop: int


@dataclass(frozen=True)
class GnssSatellite:
    """One satellite entry of GnssSatInfo."""

    gnss_id: int
    sv_id: int
    cno: int
    flags: int


@dataclass(frozen=True)
class GnssSatInfo:
    """GnssSatInfo output: an 8-byte header and 4 bytes per satellite."""

    itow: int
    num_svs: int
    res1: int
    res2: int
    res3: int
    satellites: tuple[GnssSatellite, ...] = ()


UTC_STRUCT = struct.Struct(">IH6B")
PVT_STRUCT = struct.Struct(">IH6BIi4B4i2I5i2Ii7H")
SATINFO_HEADER = struct.Struct(">I4B")
SATELLITE_STRUCT = struct.Struct(">4B")


@dataclass(frozen=True)
class DataSpec:
    """One row of the data-identifier table (``kind``: how its bytes read)."""

    name: str
    base: int
    kind: DataKind
    unit: str
    count: int = 0
    fmt: str = ""
    has_frame: bool = False
    fixed_point: bool = True

    def precisions(self) -> tuple[str, ...]:
        """Precision names this output can be configured with."""
        if self.kind != _REAL:
            return ("float32",)  # format nibble 0: integer and structured outputs have one encoding
        if not self.fixed_point:
            return ("float32", "float64")
        return tuple(PRECISIONS)

    def frames(self) -> tuple[str, ...]:
        """Coordinate frames this output can be configured with."""
        return tuple(FRAMES) if self.has_frame else ("ENU",)


def _real(
    name: str, base: int, count: int, unit: str, has_frame: bool = False, fixed_point: bool = True
) -> DataSpec:
    return DataSpec(
        name, base, DataKind.REAL, unit, count=count, has_frame=has_frame, fixed_point=fixed_point
    )


#: Every data identifier of LLCP Table 16 (reference §2.4), keyed by ``xdi & 0xFFF0``.
DATA_SPECS: tuple[DataSpec, ...] = (
    _real("Temperature", 0x0810, 1, "degC"),
    DataSpec("UtcTime", 0x1010, DataKind.UTC, "-"),
    DataSpec("PacketCounter", 0x1020, DataKind.INT, "-", fmt=">H"),
    DataSpec("SampleTimeFine", 0x1060, DataKind.INT, "0.1 ms", fmt=">I"),
    DataSpec("SampleTimeCoarse", 0x1070, DataKind.INT, "s", fmt=">I"),
    _real("Quaternion", 0x2010, 4, "-", has_frame=True),
    _real("RotationMatrix", 0x2020, 9, "-", has_frame=True),
    _real("EulerAngles", 0x2030, 3, "deg", has_frame=True),
    DataSpec("BaroPressure", 0x3010, DataKind.INT, "Pa", fmt=">I"),
    _real("DeltaV", 0x4010, 3, "m/s"),
    _real("Acceleration", 0x4020, 3, "m/s^2"),
    _real("FreeAcceleration", 0x4030, 3, "m/s^2"),
    _real("AccelerationHR", 0x4040, 3, "m/s^2"),
    _real("AltitudeEllipsoid", 0x5020, 1, "m"),
    _real("PositionEcef", 0x5030, 3, "m", fixed_point=False),
    _real("LatLon", 0x5040, 2, "deg"),
    DataSpec("GnssPvtData", 0x7010, DataKind.PVT, "-"),
    DataSpec("GnssSatInfo", 0x7020, DataKind.SATINFO, "-"),
    _real("RateOfTurn", 0x8020, 3, "rad/s"),
    _real("DeltaQ", 0x8030, 4, "-"),
    _real("RateOfTurnHR", 0x8040, 3, "rad/s"),
    DataSpec("RawAccGyrMagTemp", 0xA010, DataKind.INTS, "counts", fmt=">9Hh"),
    _real("MagneticField", 0xC020, 3, "a.u."),
    _real("VelocityXYZ", 0xD010, 3, "m/s", has_frame=True),
    DataSpec("StatusByte", 0xE010, DataKind.INT, "bits", fmt=">B"),
    DataSpec("StatusWord", 0xE020, DataKind.INT, "bits", fmt=">I"),
    DataSpec("DeviceId", 0xE080, DataKind.DEVICEID, "-"),
    DataSpec("LocationId", 0xE090, DataKind.INT, "-", fmt=">H"),
)
SPEC_BY_BASE: dict[int, DataSpec] = {spec.base: spec for spec in DATA_SPECS}
SPEC_BY_NAME: dict[str, DataSpec] = {spec.name: spec for spec in DATA_SPECS}
#: The kinds as module names: the per-item code reads them without the enum class's lookup (5x slower).
_REAL, _INT, _INTS, _UTC, _PVT, _SATINFO, _DEVICEID = DataKind  # in the order DataKind defines them


def _normalise_precision(precision: str) -> str:
    key = precision.lower().replace(".", "").replace("_", "").replace("-", "")
    if key not in PRECISIONS:
        raise ProtocolError(f"unknown precision {precision!r}; use one of {', '.join(PRECISIONS)}")
    return key


def spec_for(name: str) -> DataSpec:
    """The table row of an output by its Xsens name (ProtocolError lists the names otherwise)."""
    try:
        return SPEC_BY_NAME[name]
    except KeyError:
        raise ProtocolError(f"unknown MTData2 output {name!r}; known: {', '.join(SPEC_BY_NAME)}") from None


def make_xdi(name: str, precision: str = "float32", frame: str = "ENU") -> int:
    """The XDI for output ``name`` in ``precision`` (float32, fp1220, fp1632, float64) and ``frame``."""
    spec = spec_for(name)
    key = _normalise_precision(precision)
    if key not in spec.precisions():
        raise ProtocolError(f"{name} cannot be sent as {precision}; allowed: {', '.join(spec.precisions())}")
    frame_key = frame.upper()
    if frame_key not in spec.frames():
        raise ProtocolError(f"{name} cannot be given in frame {frame}; allowed: {', '.join(spec.frames())}")
    return spec.base | FRAMES[frame_key] | PRECISIONS[key]


def describe_xdi(xdi: int) -> str:
    """People's name of an XDI: 'EulerAngles(ENU,float32)', 'PacketCounter', or 'unknown 0x1234'."""
    spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
    if spec is None:
        return f"unknown 0x{xdi:04X}"
    if spec.kind != _REAL:
        return spec.name
    parts = [PRECISION_NAMES[xdi & PRECISION_MASK]]
    if spec.has_frame:
        parts.insert(0, FRAME_NAMES.get(xdi & FRAME_MASK, f"frame{xdi & FRAME_MASK:X}"))
    return f"{spec.name}({','.join(parts)})"


def item_size(spec: DataSpec, xdi: int) -> int | None:
    """Payload bytes of one item; None for outputs whose size varies (DeviceId, GnssSatInfo)."""
    if spec.kind == _REAL:
        return spec.count * REAL_SIZES[xdi & PRECISION_MASK]
    if spec.kind in (_INT, _INTS):
        return struct.calcsize(spec.fmt)
    if spec.kind == _UTC:
        return UTC_STRUCT.size
    if spec.kind == _PVT:
        return PVT_STRUCT.size
    return None


# ----------------------------------------------------------------------------------------- reals


def encode_reals(values: Sequence[float], precision_bits: int) -> bytes:
    """Big-endian reals in one precision; fixed point rounds to nearest and refuses out-of-range values."""
    if precision_bits == PRECISIONS["float32"]:
        return struct.pack(f">{len(values)}f", *values)
    if precision_bits == PRECISIONS["float64"]:
        return struct.pack(f">{len(values)}d", *values)
    out = bytearray()
    for value in values:
        if precision_bits == PRECISIONS["fp1220"]:
            raw = round(value * FP1220_SCALE)
            if not -(1 << 31) <= raw < (1 << 31):
                raise ProtocolError(f"{value} is outside the FP12.20 range [-2048, 2048)")
            out += struct.pack(">i", raw)
        else:
            raw = round(value * FP1632_SCALE)
            if not -(1 << 47) <= raw < (1 << 47):
                raise ProtocolError(f"{value} is outside the FP16.32 range [-32768, 32768)")
            out += struct.pack(">Ih", raw & 0xFFFFFFFF, raw >> 32)  # fraction first, then integer part
    return bytes(out)


def decode_reals(data: bytes, precision_bits: int) -> tuple[float, ...]:
    """Inverse of ``encode_reals``; fixed point decodes exactly (the scale is a power of two)."""
    if precision_bits == PRECISIONS["float32"]:
        return struct.unpack(f">{len(data) // 4}f", data)
    if precision_bits == PRECISIONS["float64"]:
        return struct.unpack(f">{len(data) // 8}d", data)
    if precision_bits == PRECISIONS["fp1220"]:
        return tuple(raw / FP1220_SCALE for raw in struct.unpack(f">{len(data) // 4}i", data))
    pairs = struct.unpack(f">{len(data) // 6 * 'Ih'}", data)
    return tuple((pairs[i + 1] * FP1632_SCALE + pairs[i]) / FP1632_SCALE for i in range(0, len(pairs), 2))


# ----------------------------------------------------------------------------------------- items


def encode_value(xdi: int, value: Any) -> bytes:
    """The DATA bytes of one item; ``bytes`` are passed through for the structured outputs."""
    spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
    if spec is None:
        if isinstance(value, bytes | bytearray):
            return bytes(value)  # unknown identifiers can still be sent raw (tests, simulators)
        raise ProtocolError(f"unknown data identifier 0x{xdi:04X}: give its value as bytes")
    if isinstance(value, bytes | bytearray) and spec.kind != _REAL:
        return bytes(value)
    try:
        if spec.kind == _REAL:
            values = (value,) if isinstance(value, int | float) else tuple(value)
            if len(values) != spec.count:
                raise ProtocolError(f"{spec.name} takes {spec.count} values, got {len(values)}")
            return encode_reals(values, xdi & PRECISION_MASK)
        if spec.kind == _INT:
            return struct.pack(spec.fmt, value)
        if spec.kind == _INTS:
            return struct.pack(spec.fmt, *value)
        if spec.kind == _DEVICEID:
            return struct.pack(">Q" if value > 0xFFFFFFFF else ">I", value)
        if spec.kind == _UTC:
            return UTC_STRUCT.pack(*astuple(value))
        if spec.kind == _PVT:
            return PVT_STRUCT.pack(*astuple(value))
        header = SATINFO_HEADER.pack(value.itow, value.num_svs, value.res1, value.res2, value.res3)
        return header + b"".join(SATELLITE_STRUCT.pack(*astuple(sat)) for sat in value.satellites)
    except (struct.error, TypeError, AttributeError) as exc:
        raise ProtocolError(f"cannot encode {value!r} as {spec.name}: {exc}") from None


def decode_value(spec: DataSpec, xdi: int, data: bytes) -> object:
    """One item's value in device units; ProtocolError when DATA has the wrong size for the XDI."""
    expected = item_size(spec, xdi)
    if expected is not None and len(data) != expected:
        raise ProtocolError(f"{describe_xdi(xdi)} needs {expected} data bytes, the message gives {len(data)}")
    if spec.kind == _REAL:
        values = decode_reals(data, xdi & PRECISION_MASK)
        return values[0] if spec.count == 1 else values
    if spec.kind == _INT:
        return struct.unpack(spec.fmt, data)[0]
    if spec.kind == _INTS:
        return struct.unpack(spec.fmt, data)
    if spec.kind == _UTC:
        return UtcTime(*UTC_STRUCT.unpack(data))
    if spec.kind == _PVT:
        return GnssPvt(*PVT_STRUCT.unpack(data))
    if spec.kind == _DEVICEID:
        if len(data) not in (4, 8):
            raise ProtocolError(f"DeviceId needs 4 or 8 data bytes, the message gives {len(data)}")
        return int.from_bytes(data, "big")
    return decode_satinfo(data)


def decode_satinfo(data: bytes) -> GnssSatInfo:
    """GnssSatInfo: header, then ``num_svs`` 4-byte satellite entries (the size must agree)."""
    if len(data) < SATINFO_HEADER.size or (len(data) - SATINFO_HEADER.size) % SATELLITE_STRUCT.size:
        raise ProtocolError(f"GnssSatInfo of {len(data)} bytes is not 8 + 4 per satellite")
    itow, num_svs, res1, res2, res3 = SATINFO_HEADER.unpack_from(data)
    satellites = tuple(
        GnssSatellite(*SATELLITE_STRUCT.unpack_from(data, offset))
        for offset in range(SATINFO_HEADER.size, len(data), SATELLITE_STRUCT.size)
    )
    return GnssSatInfo(itow, num_svs, res1, res2, res3, satellites)


def encode_mtdata2(items: Sequence[tuple[int, object]]) -> bytes:
    """MTData2 payload from (xdi, value) pairs, in the order given."""
    out = bytearray()
    for xdi, value in items:
        data = encode_value(xdi, value)
        if len(data) > 0xFF:
            raise ProtocolError(
                f"{describe_xdi(xdi)} data of {len(data)} bytes does not fit one MTData2 item"
            )
        out += struct.pack(">HB", xdi, len(data)) + data
    return bytes(out)


class MTData2Message(Mapping[str, object]):
    """One decoded MTData2 message: Xsens name -> value in device units, plus each item's XDI."""

    __slots__ = ("_values", "unknown_xdis", "xdis")

    def __init__(self, values: dict[str, object], xdis: dict[str, int], unknown_xdis: tuple[int, ...] = ()):
        self._values = values
        self.xdis = xdis
        self.unknown_xdis = unknown_xdis

    def __getitem__(self, name: str) -> object:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"MTData2Message({self._values!r})"

    @property
    def unknown_count(self) -> int:
        """Items skipped because their identifier is not in the table."""
        return len(self.unknown_xdis)

    def precision(self, name: str) -> str:
        """The precision the item ``name`` was sent in."""
        return PRECISION_NAMES[self.xdis[name] & PRECISION_MASK]

    def frame(self, name: str) -> str:
        """The coordinate frame of item ``name`` (ENU for outputs without frame bits)."""
        return FRAME_NAMES.get(self.xdis[name] & FRAME_MASK, "ENU")


def item_spans(payload: bytes) -> list[tuple[int, int, int]]:
    """(xdi, data offset, size) of every item; ProtocolError when the sizes do not add up to the payload."""
    spans = []
    pos = 0
    end = len(payload)
    while pos < end:
        if end - pos < 3:
            raise ProtocolError(f"MTData2 payload ends inside an item header at byte {pos} of {end}")
        xdi, size = struct.unpack_from(">HB", payload, pos)
        pos += 3
        if pos + size > end:
            raise ProtocolError(f"MTData2 item 0x{xdi:04X} claims {size} bytes but only {end - pos} remain")
        spans.append((xdi, pos, size))
        pos += size
    return spans


def payload_well_formed(payload: bytes) -> bool:
    """True when an MTData2 payload decodes (``decode_mtdata2`` would not raise): item sizes add up and
    every known item has a size its identifier allows. Only sizes are looked at (decoding a value
    never fails on its bytes), so this is cheap enough for every candidate frame that needs it."""
    pos, end = 0, len(payload)
    while pos < end:
        if end - pos < 3:
            return False
        xdi, size = payload[pos] << 8 | payload[pos + 1], payload[pos + 2]
        pos += 3 + size
        if pos > end:
            return False
        spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
        if spec is None:
            continue
        expected = item_size(spec, xdi)
        if expected is not None:
            if size != expected:
                return False
        elif spec.kind == _DEVICEID:
            if size not in (4, 8):
                return False
        elif size < SATINFO_HEADER.size or (size - SATINFO_HEADER.size) % SATELLITE_STRUCT.size:
            return False
    return True


def decode_mtdata2(payload: bytes) -> MTData2Message:
    """Decode one MTData2 payload; unknown identifiers are skipped by size and counted, never fatal."""
    values: dict[str, object] = {}
    xdis: dict[str, int] = {}
    unknown: list[int] = []
    for xdi, offset, size in item_spans(payload):
        spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
        if spec is None:
            unknown.append(xdi)
            continue
        values[spec.name] = decode_value(spec, xdi, bytes(payload[offset : offset + size]))
        xdis[spec.name] = xdi
    return MTData2Message(values, xdis, tuple(unknown))


def to_jsonable(value: object) -> object:
    """A JSON-ready form of a decoded value: tuples -> lists, structured outputs -> dicts."""
    if isinstance(value, UtcTime):
        fields_ = {f.name: getattr(value, f.name) for f in fields(value)}
        return {**fields_, "iso": value.isoformat(), "valid": value.valid}
    if isinstance(value, GnssPvt | GnssSatellite):
        return {f.name: getattr(value, f.name) for f in fields(value)}
    if isinstance(value, GnssSatInfo):
        head = {f.name: getattr(value, f.name) for f in fields(value) if f.name != "satellites"}
        return {**head, "satellites": [to_jsonable(sat) for sat in value.satellites]}
    if isinstance(value, tuple | list):
        return [to_jsonable(v) for v in value]
    return value
