"""Xbus message ids, device error codes and baud-rate codes (LLCP §5, Tables 5 and 7).

Req and Set messages share one id (an empty payload asks, a non-empty one sets); the
reply to id ``n`` is ``n + 1``.
"""

from __future__ import annotations

from enum import IntEnum, StrEnum

from ..errors import ProtocolError

PREAMBLE = 0xFA
MASTER_BID = 0xFF
EXTENDED_LENGTH = 0xFF
MAX_DATA_LENGTH = 2048


class MID(IntEnum):
    """Xbus message identifiers (LLCP §5.3; xspublic ``xsxbusmessageid.h``)."""

    REQ_DID = 0x00
    DEVICE_ID = 0x01
    PERIOD = 0x04
    PERIOD_ACK = 0x05
    REQ_CONFIGURATION = 0x0C
    CONFIGURATION = 0x0D
    RESTORE_FACTORY_DEF = 0x0E
    RESTORE_FACTORY_DEF_ACK = 0x0F
    GOTO_MEASUREMENT = 0x10
    GOTO_MEASUREMENT_ACK = 0x11
    REQ_FW_REV = 0x12
    FW_REV = 0x13
    REQ_BAUDRATE = 0x18
    BAUDRATE_ACK = 0x19
    REQ_PRODUCT_CODE = 0x1C
    PRODUCT_CODE = 0x1D
    REQ_HARDWARE_VERSION = 0x1E
    HARDWARE_VERSION = 0x1F
    SET_NO_ROTATION = 0x22
    SET_NO_ROTATION_ACK = 0x23
    RUN_SELFTEST = 0x24
    SELFTEST_ACK = 0x25
    SYNC_SETTINGS = 0x2C
    SYNC_SETTINGS_ACK = 0x2D
    GOTO_CONFIG = 0x30
    GOTO_CONFIG_ACK = 0x31
    MTDATA = 0x32
    REQ_DATA = 0x34
    MTDATA2 = 0x36
    WAKEUP = 0x3E
    WAKEUP_ACK = 0x3F
    RESET = 0x40
    RESET_ACK = 0x41
    ERROR = 0x42
    OPTION_FLAGS = 0x48
    OPTION_FLAGS_ACK = 0x49
    UTC_TIME = 0x60
    UTC_TIME_ACK = 0x61
    FILTER_PROFILE = 0x64
    FILTER_PROFILE_ACK = 0x65
    LAT_LON_ALT = 0x6E
    LAT_LON_ALT_ACK = 0x6F
    GNSS_PLATFORM = 0x76
    GNSS_PLATFORM_ACK = 0x77
    LOCATION_ID = 0x84
    LOCATION_ID_ACK = 0x85
    PORT_CONFIG = 0x8C
    PORT_CONFIG_ACK = 0x8D
    STRING_OUTPUT_TYPE = 0x8E
    STRING_OUTPUT_TYPE_ACK = 0x8F
    RESET_ORIENTATION = 0xA4
    RESET_ORIENTATION_ACK = 0xA5
    ADJUST_UTC_TIME = 0xA8
    ADJUST_UTC_TIME_ACK = 0xA9
    OUTPUT_CONFIGURATION = 0xC0
    OUTPUT_CONFIGURATION_ACK = 0xC1
    OUTPUT_MODE = 0xD0
    OUTPUT_MODE_ACK = 0xD1
    OUTPUT_SETTINGS = 0xD2
    OUTPUT_SETTINGS_ACK = 0xD3
    OUTPUT_SKIP_FACTOR = 0xD4
    OUTPUT_SKIP_FACTOR_ACK = 0xD5

    # Req and Set share one id; the aliases make call sites read as what they do.
    SET_BAUDRATE = 0x18
    SET_OUTPUT_CONFIGURATION = 0xC0
    SET_OUTPUT_MODE = 0xD0
    SET_OUTPUT_SETTINGS = 0xD2
    SET_PERIOD = 0x04
    SET_PORT_CONFIG = 0x8C


#: Device error codes carried by an Error (0x42) message (LLCP Table 5; xspublic ``xsresultvalue.h``).
ERROR_NAMES: dict[int, str] = {
    0x03: "invalid period",
    0x04: "message invalid or not implemented",
    0x1E: "timer overflow: output rate too high or too much data sent to the device",
    0x20: "invalid baud rate",
    0x21: "invalid parameter",
    0x28: "device error",
    0x29: "data overflow: more data than the serial link carries",
    0x2A: "sample buffer full during a communication outage",
}

#: Baud-rate code -> rate in bit/s (LLCP Table 7). 0x0A and 0x80 both mean 921600.
BAUD_CODES: dict[int, int] = {
    0x00: 460800,
    0x01: 230400,
    0x02: 115200,
    0x03: 76800,
    0x04: 57600,
    0x05: 38400,
    0x06: 28800,
    0x07: 19200,
    0x08: 14400,
    0x09: 9600,
    0x0A: 921600,
    0x0B: 4800,
    0x0C: 2_000_000,
    0x0D: 4_000_000,
    0x0E: 3_686_400,
    0x80: 921600,
}

#: Rates of the serial interface (LLCP §7.2.1: 4800..921600), slowest first.
SERIAL_BAUDS: tuple[int, ...] = tuple(sorted(rate for rate in set(BAUD_CODES.values()) if rate <= 921600))
#: The order the driver looks for a device in: factory default first, then the fast rates tests use.
SEARCH_BAUDS: tuple[int, ...] = (115200, 921600, 460800, 230400, 57600, 38400, 19200, 9600)
#: Messages that write the device's flash: their ack can take hundreds of milliseconds.
FLASH_WRITES = frozenset(
    (MID.OUTPUT_CONFIGURATION, MID.SET_BAUDRATE, MID.SET_PORT_CONFIG, MID.RESTORE_FACTORY_DEF,
     MID.OUTPUT_MODE, MID.OUTPUT_SETTINGS, MID.PERIOD)
)  # fmt: skip

# 0x80 is the legacy 921600 code every firmware accepts; 0x0A needs FW >= 2.4.6.
_CODE_FOR_RATE: dict[int, int] = {rate: code for code, rate in BAUD_CODES.items() if code != 0x0A}


def baud_code(rate: int) -> int:
    """The code to send in SetBaudrate for ``rate`` bit/s (921600 -> 0x80, which every firmware knows)."""
    try:
        return _CODE_FOR_RATE[rate]
    except KeyError:
        known = ", ".join(str(r) for r in sorted(_CODE_FOR_RATE))
        raise ProtocolError(f"unsupported baud rate {rate}; the MT knows {known}") from None


def error_name(code: int) -> str:
    """Readable meaning of a device error code (unknown codes are named by their number)."""
    return ERROR_NAMES.get(code, f"unknown device error 0x{code:02X}")


class DataKind(StrEnum):
    """How an output's data bytes read: ``REAL`` (``count`` values in the XDI's precision), ``INT`` (one
    unsigned field, struct ``fmt``), ``INTS`` (a tuple of integers, ``fmt``), or one of the structured
    outputs (``DEVICEID``: U4 or U8)."""

    REAL = "real"
    INT = "int"
    INTS = "ints"
    UTC = "utc"
    PVT = "pvt"
    SATINFO = "satinfo"
    DEVICEID = "deviceid"
