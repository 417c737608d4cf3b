"""Legacy MTData (MID 0x32) of the 2005-2008 MTi-G (Mark III), reference §4.

A legacy message has no item headers: its content follows from OutputMode (which blocks)
and OutputSettings (timestamp, orientation form, disabled sensors, precision, frame), in a
fixed block order. Decoded values use the MTData2 names and device units, so a legacy
device feeds the same code paths (EulerAngles in degrees, Acceleration in m/s², ...).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import astuple, dataclass
from enum import StrEnum
from typing import Any

from ..errors import ProtocolError
from .mtdata2 import (
    PRECISIONS,
    REAL_SIZES,
    UTC_STRUCT,
    MTData2Message,
    UtcTime,
    decode_reals,
    encode_reals,
    make_xdi,
)

# OutputMode bits (MT0100P p. 28; ethz mtdef.py)
MODE_TEMPERATURE = 0x0001
MODE_CALIBRATED = 0x0002
MODE_ORIENTATION = 0x0004
MODE_AUXILIARY = 0x0008
MODE_POSITION = 0x0010
MODE_VELOCITY = 0x0020
MODE_STATUS = 0x0800
MODE_RAW_GPS = 0x1000
MODE_RAW_INERTIAL = 0x4000
KNOWN_MODE_BITS = (
    MODE_TEMPERATURE | MODE_CALIBRATED | MODE_ORIENTATION | MODE_AUXILIARY | MODE_POSITION | MODE_VELOCITY
    | MODE_STATUS | MODE_RAW_GPS | MODE_RAW_INERTIAL
)  # fmt: skip

# OutputSettings fields
TIMESTAMP_MASK = 0x0003  # 0 none, 1 sample counter, 2 UTC
ORIENTATION_MASK = 0x000C  # 0 quaternion, 4 Euler, 8 matrix
DISABLE_ACC, DISABLE_GYR, DISABLE_MAG = 0x0010, 0x0020, 0x0040
PRECISION_SHIFT, PRECISION_FIELD = 8, 0x0300  # 0 float32, 1 FP12.20, 2 FP16.32
DISABLE_AIN1, DISABLE_AIN2 = 0x0400, 0x0800
POSITION_MODE_MASK = 0x1C000  # only 0 (LLA, WGS84) is defined
VELOCITY_MODE_MASK = 0x60000  # only 0 (m/s, XYZ) is defined
NED_BIT = 0x80000000

ORIENTATIONS = {0x0: ("Quaternion", 4), 0x4: ("EulerAngles", 3), 0x8: ("RotationMatrix", 9)}
RAW_INERTIAL = struct.Struct(">10H")  # acc, gyr, mag xyz counts, temperature counts
RAW_GPS = struct.Struct(">HBI3i3i3IB")
COUNTER = struct.Struct(">H")
STATUS = struct.Struct(">B")


@dataclass(frozen=True)
class RawGps:
    """Legacy raw GPS + pressure block (u-blox units: 1e-7 deg, mm, cm/s, mm; pressure in counts)."""

    pressure: int
    pressure_age: int
    itow: int
    lat: int
    lon: int
    alt: int
    vel_n: int
    vel_e: int
    vel_d: int
    h_acc: int
    v_acc: int
    s_acc: int
    gps_age: int


class BlockKind(StrEnum):
    """How a legacy block reads: ``REALS`` (``count`` values in the message precision), or by its ``fmt``."""

    REALS = "reals"
    INTS = "ints"
    UTC = "utc"
    RAWGPS = "rawgps"


#: The blocks read into a structured value, by kind; the per-block code reads ``_REALS`` without the enum
#: class's lookup (5x slower).
STRUCTURED: dict[BlockKind, type] = {BlockKind.UTC: UtcTime, BlockKind.RAWGPS: RawGps}
_REALS = BlockKind.REALS


@dataclass(frozen=True)
class LegacyBlock:
    """One block of a legacy message: the name it decodes to, its kind and its value count."""

    name: str
    kind: BlockKind
    count: int = 0
    fmt: struct.Struct = COUNTER

    def size(self, precision_bits: int) -> int:
        """Bytes of this block in a message of the given precision."""
        return self.count * REAL_SIZES[precision_bits] if self.kind == _REALS else self.fmt.size


@dataclass(frozen=True)
class LegacyLayout:
    """The blocks of a legacy message and the precision of its real values."""

    blocks: tuple[LegacyBlock, ...]
    precision_bits: int
    frame: str

    @property
    def length(self) -> int:
        """Data bytes of one MTData message (what Configuration reports as the data length)."""
        return sum(block.size(self.precision_bits) for block in self.blocks)


def legacy_layout(output_mode: int, output_settings: int) -> LegacyLayout:
    """The order of blocks for an OutputMode/OutputSettings pair; ProtocolError for pairs that cannot be."""
    if output_mode & ~KNOWN_MODE_BITS:
        raise ProtocolError(f"output mode 0x{output_mode:04X} has bits tankdaq does not know")
    timestamp = output_settings & TIMESTAMP_MASK
    if timestamp == 3:
        raise ProtocolError("output settings timestamp field 3 is not defined (0 none, 1 counter, 2 UTC)")
    precision_bits = (output_settings & PRECISION_FIELD) >> PRECISION_SHIFT
    if precision_bits == 3:
        raise ProtocolError("output settings precision field 3 is not defined (float32, FP12.20, FP16.32)")
    if output_settings & ORIENTATION_MASK == ORIENTATION_MASK:
        raise ProtocolError(
            "output settings orientation field 0xC is not defined (quaternion, Euler, matrix)"
        )
    if output_settings & (POSITION_MODE_MASK | VELOCITY_MODE_MASK):
        raise ProtocolError("only LLA position and XYZ velocity output modes are supported")
    blocks: list[LegacyBlock] = []
    if output_mode & MODE_RAW_INERTIAL:
        blocks.append(LegacyBlock("RawAccGyrMagTemp", BlockKind.INTS, fmt=RAW_INERTIAL))
    if output_mode & MODE_RAW_GPS:
        blocks.append(LegacyBlock("RawGpsPressure", BlockKind.RAWGPS, fmt=RAW_GPS))
    if output_mode & MODE_TEMPERATURE:
        blocks.append(LegacyBlock("Temperature", BlockKind.REALS, 1))
    if output_mode & MODE_CALIBRATED:
        for name, disabled in (("Acceleration", DISABLE_ACC), ("RateOfTurn", DISABLE_GYR),
                               ("MagneticField", DISABLE_MAG)):  # fmt: skip
            if not output_settings & disabled:
                blocks.append(LegacyBlock(name, BlockKind.REALS, 3))
    if output_mode & MODE_ORIENTATION:
        name, count = ORIENTATIONS[output_settings & ORIENTATION_MASK]
        blocks.append(LegacyBlock(name, BlockKind.REALS, count))
    if output_mode & MODE_AUXILIARY:
        for name, disabled in (("AnalogIn1", DISABLE_AIN1), ("AnalogIn2", DISABLE_AIN2)):
            if not output_settings & disabled:
                blocks.append(LegacyBlock(name, BlockKind.INTS, fmt=COUNTER))
    if output_mode & MODE_POSITION:
        blocks += [
            LegacyBlock("LatLon", BlockKind.REALS, 2),
            LegacyBlock("AltitudeEllipsoid", BlockKind.REALS, 1),
        ]
    if output_mode & MODE_VELOCITY:
        blocks.append(LegacyBlock("VelocityXYZ", BlockKind.REALS, 3))
    if output_mode & MODE_STATUS:
        blocks.append(LegacyBlock("StatusByte", BlockKind.INTS, fmt=STATUS))
    if timestamp == 1:
        blocks.append(LegacyBlock("PacketCounter", BlockKind.INTS, fmt=COUNTER))
    if timestamp == 2:
        blocks.append(LegacyBlock("UtcTime", BlockKind.UTC, fmt=UTC_STRUCT))
    frame = "NED" if output_settings & NED_BIT else "ENU"
    return LegacyLayout(tuple(blocks), precision_bits, frame)


def _equivalent_xdi(name: str, layout: LegacyLayout) -> int | None:
    """The MTData2 identifier with the same meaning, so ``precision()``/``frame()`` work on legacy data."""
    precision = {v: k for k, v in PRECISIONS.items()}[layout.precision_bits]
    if name in ("RawGpsPressure", "AnalogIn1", "AnalogIn2"):
        return None
    if name in ("Quaternion", "EulerAngles", "RotationMatrix", "VelocityXYZ"):
        return make_xdi(name, precision, layout.frame)
    if name in ("PacketCounter", "StatusByte", "UtcTime", "RawAccGyrMagTemp"):
        return make_xdi(name)
    return make_xdi(name, precision)


def decode_mtdata(payload: bytes, output_mode: int, output_settings: int) -> MTData2Message:
    """Decode one legacy MTData payload with the names and units of ``decode_mtdata2``."""
    layout = legacy_layout(output_mode, output_settings)
    if len(payload) != layout.length:
        raise ProtocolError(
            f"MTData of {len(payload)} bytes does not match output mode 0x{output_mode:04X} / settings "
            f"0x{output_settings:08X} ({layout.length} bytes): re-read the device configuration"
        )
    values: dict[str, object] = {}
    xdis: dict[str, int] = {}
    pos = 0
    for block in layout.blocks:
        size = block.size(layout.precision_bits)
        if block.kind == _REALS:
            reals = decode_reals(payload[pos : pos + size], layout.precision_bits)
            values[block.name] = reals[0] if block.count == 1 else reals
        else:
            fields = block.fmt.unpack_from(payload, pos)
            values[block.name] = (
                STRUCTURED[block.kind](*fields)
                if block.kind in STRUCTURED
                else (fields[0] if len(fields) == 1 else fields)
            )
        xdi = _equivalent_xdi(block.name, layout)
        if xdi is not None:
            xdis[block.name] = xdi
        pos += size
    return MTData2Message(values, xdis)


def encode_mtdata(values: Mapping[str, object], output_mode: int, output_settings: int) -> bytes:
    """A legacy MTData payload (for simulators and tests); every block of the layout needs a value."""
    layout = legacy_layout(output_mode, output_settings)
    missing = [b.name for b in layout.blocks if b.name not in values]
    if missing:
        raise ProtocolError(f"legacy output mode 0x{output_mode:04X} needs values for {', '.join(missing)}")
    out = bytearray()
    for block in layout.blocks:
        value: Any = values[block.name]
        try:
            if block.kind == _REALS:
                reals = (value,) if isinstance(value, int | float) else tuple(value)
                if len(reals) != block.count:
                    raise ProtocolError(f"{block.name} takes {block.count} values, got {len(reals)}")
                out += encode_reals(reals, layout.precision_bits)
            elif block.kind in STRUCTURED:
                out += block.fmt.pack(*astuple(value))
            else:
                out += block.fmt.pack(*(value if isinstance(value, tuple) else (value,)))
        except (struct.error, TypeError) as exc:
            raise ProtocolError(f"cannot encode {value!r} as legacy {block.name}: {exc}") from None
    return bytes(out)


@dataclass(frozen=True)
class DeviceConfiguration:
    """The parts of a Configuration (0x0D) reply tankdaq uses (LLCP Table 13; 118 bytes)."""

    master_id: int
    period: int  # in 1/115200 s
    skip_factor: int
    num_devices: int
    device_id: int
    data_length: int
    output_mode: int
    output_settings: int

    @property
    def sample_rate_hz(self) -> float:
        """Output rate of a legacy device: 115200 / (period · (skip + 1))."""
        return 115200 / (self.period * (self.skip_factor + 1))

    @property
    def is_legacy_output(self) -> bool:
        """True when the device streams legacy MTData (an output mode is set)."""
        return self.output_mode != 0


CONFIGURATION_LENGTH = 118


def parse_configuration(payload: bytes) -> DeviceConfiguration:
    """Fields of a Configuration reply; ProtocolError when it is not the 118-byte form."""
    if len(payload) != CONFIGURATION_LENGTH:
        raise ProtocolError(f"configuration reply of {len(payload)} bytes (expected {CONFIGURATION_LENGTH})")
    master_id, period, skip = struct.unpack_from(">IHH", payload, 0)
    num_devices, device_id, data_length, mode, settings = struct.unpack_from(">HIHHI", payload, 96)
    return DeviceConfiguration(master_id, period, skip, num_devices, device_id, data_length, mode, settings)
