"""Payload builders and parsers for the configuration messages (reference §3).

The driver composes these with ``build_frame``; nothing here touches a port.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import ProtocolError
from .constants import BAUD_CODES, SERIAL_BAUDS, baud_code, error_name
from .mtdata2 import SPEC_BY_BASE, TYPE_MASK, item_size, make_xdi

#: Frequency that means "as fast as possible"; counters, time and status always read back as this.
MAX_FREQUENCY = 0xFFFF
MAX_OUTPUT_ENTRIES = 32
#: Highest output rate of the orientation/inertial groups on an MTi-G-710 (LLCP Table 16).
MAX_RATE_HZ = 400
#: 8N1 serial framing: start bit + 8 data bits + stop bit.
BITS_PER_BYTE = 10
#: Per-message bytes around the items: FA BID MID LEN ... CS.
FRAME_OVERHEAD = 5
#: A GnssSatInfo budget: header + 32 satellites (its size varies with the sky).
SATINFO_BUDGET_BYTES = 8 + 4 * 32

#: The outputs a decay test needs: counter, device time, attitude, rates, accelerations, status.
DECAY_OUTPUTS: tuple[str, ...] = (
    "PacketCounter",
    "SampleTimeFine",
    "EulerAngles",
    "RateOfTurn",
    "Acceleration",
    "StatusWord",
)
#: The orientation outputs asked for, best first: the one a device refuses is replaced by the next
#: (each gives the same roll and pitch, ``xsens.orientation``); with none, the rate of turn is integrated.
ORIENTATION_OUTPUTS: tuple[str, ...] = ("EulerAngles", "Quaternion", "RotationMatrix")
ORIENTATION_WORDS = {
    "EulerAngles": "Euler angles",
    "Quaternion": "quaternion",
    "RotationMatrix": "rotation matrix",
}
#: The orientation source of a device without orientation output (a recording's ``orientation_source``).
INTEGRATED_RATE_OF_TURN = "integrated rate of turn"
#: The error a device answers to an output it does not have (invalid parameter): try the next one.
ERROR_INVALID_PARAMETER = 0x21
#: Outputs that ride along with every message (their frequency is ignored by the device).
PER_MESSAGE_OUTPUTS = frozenset(
    {"PacketCounter", "SampleTimeFine", "SampleTimeCoarse", "UtcTime", "StatusByte", "StatusWord"}
)


def output_configuration_payload(entries: Sequence[tuple[int, int]]) -> bytes:
    """SetOutputConfiguration data: (xdi, Hz) pairs, 0xFFFF = maximum rate, at most 32 entries."""
    if not entries or len(entries) > MAX_OUTPUT_ENTRIES:
        raise ProtocolError(
            f"an output configuration holds 1 to {MAX_OUTPUT_ENTRIES} entries, got {len(entries)}"
        )
    for xdi, hz in entries:
        if not (0 <= xdi <= 0xFFFF and 0 <= hz <= 0xFFFF):
            raise ProtocolError(f"output entry (0x{xdi:X}, {hz} Hz): identifier and rate must fit in 16 bits")
    return b"".join(struct.pack(">HH", xdi, hz) for xdi, hz in entries)


def parse_output_configuration(payload: bytes) -> list[tuple[int, int]]:
    """(xdi, Hz) pairs of an output configuration (the ack echoes what the device accepted)."""
    if len(payload) % 4:
        raise ProtocolError(
            f"output configuration of {len(payload)} bytes is not a whole number of 4-byte entries"
        )
    return [struct.unpack_from(">HH", payload, offset) for offset in range(0, len(payload), 4)]


def decay_output_configuration(
    rate_hz: int, precision: str = "float32", orientation: str | None = "EulerAngles"
) -> list[tuple[int, int]]:
    """The decay-test output set at ``rate_hz`` (counters, time and status at 0xFFFF), with
    ``orientation`` (one of ``ORIENTATION_OUTPUTS``; None: no orientation) in place of Euler angles."""
    if not 1 <= rate_hz <= MAX_RATE_HZ:
        raise ProtocolError(f"output rate {rate_hz} Hz is outside 1..{MAX_RATE_HZ} Hz (MTi-G-710 maximum)")
    if orientation is not None and orientation not in ORIENTATION_OUTPUTS:
        raise ProtocolError(
            f"{orientation!r} is not an orientation output ({', '.join(ORIENTATION_OUTPUTS)})"
        )
    names = [orientation if name == "EulerAngles" else name for name in DECAY_OUTPUTS]
    return [
        (make_xdi(name), MAX_FREQUENCY)
        if name in PER_MESSAGE_OUTPUTS
        else (make_xdi(name, precision), rate_hz)
        for name in names
        if name is not None
    ]


def is_imu_class(product_code: str) -> bool:
    """An IMU-class product (MTi-1, MTi-10, MTi-100, MTi-610): rate of turn and acceleration, no
    orientation output [inference from the product families' naming: x1/x10/x100/610 IMU, x2/x20/x200/620
    VRU, x3/x30/x300/630 AHRS]."""
    return re.match(r"MTi-(1|10|100|610)(-|$)", product_code) is not None


@dataclass(frozen=True)
class OrientationSource:
    """Where a device's roll and pitch come from: the orientation output it accepted (None: none, the
    rate of turn is integrated), what it refused on the way (output, error code), and whether its
    product code said it has no orientation output (then none was asked for)."""

    output: str | None = "EulerAngles"
    refused: tuple[tuple[str, int], ...] = ()
    imu_class: bool = False

    @property
    def integrated(self) -> bool:
        return self.output is None

    @property
    def label(self) -> str:
        """A recording's ``orientation_source``: the output in words, or the integrated rate of turn."""
        return INTEGRATED_RATE_OF_TURN if self.output is None else ORIENTATION_WORDS[self.output]

    def metadata(self) -> dict[str, str]:
        """What a recording keeps: ``orientation_source``, and ``orientation_refused`` when anything was."""
        refused = ", ".join(f"{ORIENTATION_WORDS[name]} (error 0x{code:02X})" for name, code in self.refused)
        return {"orientation_source": self.label, **({"orientation_refused": refused} if refused else {})}

    def line(self) -> str | None:
        """The one line a recorder says when roll and pitch do not come from Euler angles (None: they do)."""
        if self.output == "EulerAngles":
            return None
        if self.imu_class:
            why = "the device is an IMU-class product (no orientation output)"
        else:
            names = [ORIENTATION_WORDS[name] for name, _ in self.refused]
            listed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
            codes = sorted({f"0x{code:02X}" for _, code in self.refused})
            why = f"the device refused {listed} (error {', '.join(codes)})"
        if self.output is None:
            return (
                f"{why}: roll and pitch come from its rate of turn integrated over the decay, anchored by "
                "gravity at rest before the release"
            )
        return f"{why}: roll and pitch come from its {ORIENTATION_WORDS[self.output]}"


def _entry_bytes(xdi: int) -> int:
    spec = SPEC_BY_BASE.get(xdi & TYPE_MASK)
    if spec is None:
        raise ProtocolError(f"unknown data identifier 0x{xdi:04X}: its size is not known")
    size = item_size(spec, xdi)
    if size is None:
        size = SATINFO_BUDGET_BYTES if spec.name == "GnssSatInfo" else 8
    return 3 + size


def frame_bytes_per_second(entries: Sequence[tuple[int, int]], rate_hz: float) -> float:
    """Serial bytes per second when MTData2 messages go out at ``rate_hz``.

    Every message carries the per-message outputs; an output configured slower than the
    message rate adds its bytes only at its own rate. Outputs at other rates (GNSS) in fact
    travel in separate messages, so this is a slight underestimate for them.
    """
    total = FRAME_OVERHEAD * rate_hz
    for xdi, hz in entries:
        per_message = hz in (0, MAX_FREQUENCY) or SPEC_BY_BASE.get(xdi & TYPE_MASK) is None
        total += _entry_bytes(xdi) * (rate_hz if per_message else min(hz, rate_hz))
    return total


@dataclass(frozen=True)
class Bandwidth:
    """How much of a serial link an output configuration uses."""

    bits_per_second: float
    baud: int
    headroom: float

    @property
    def utilisation(self) -> float:
        """Fraction of the link's bit rate the data needs."""
        return self.bits_per_second / self.baud

    @property
    def ok(self) -> bool:
        """True when the data fits with the headroom left for acks and bursts."""
        return self.utilisation <= self.headroom

    def message(self) -> str:
        """One line a person can act on."""
        need = f"{self.bits_per_second / 1000:.1f} kbit/s ({self.utilisation:.0%} of {self.baud} baud)"
        if self.ok:
            return f"output needs {need}"
        faster = slowest_baud_carrying(self.bits_per_second, self.headroom)
        hint = f"use at least {faster} baud" if faster else "lower the rate or drop outputs"
        return f"output needs {need}, over the {self.headroom:.0%} budget: {hint}"


def check_bandwidth(
    entries: Sequence[tuple[int, int]], rate_hz: float, baud: int, headroom: float = 0.9
) -> Bandwidth:
    """Bits per second (8N1) the configuration needs at ``rate_hz`` against ``baud``."""
    return Bandwidth(frame_bytes_per_second(entries, rate_hz) * BITS_PER_BYTE, baud, headroom)


def slowest_baud_carrying(bits_per_second: float, headroom: float = 0.9) -> int | None:
    """The slowest serial rate that carries ``bits_per_second`` within the headroom (None: none does)."""
    return next((rate for rate in SERIAL_BAUDS if bits_per_second <= rate * headroom), None)


def line_refusal(bits_per_second: float, rate_hz: float, baud: int, headroom: float = 0.9) -> str | None:
    """Why ``baud`` cannot carry ``bits_per_second`` at ``rate_hz``, with the numbers (None: it can)."""
    if bits_per_second <= headroom * baud:
        return None
    need = f"{rate_hz:g} Hz needs {bits_per_second / 1000:.1f} kbit/s"
    slowest = slowest_baud_carrying(bits_per_second, headroom)
    if slowest is None:
        top = SERIAL_BAUDS[-1]
        return f"{need}; no serial rate carries it ({top} baud: {top / 1000:.1f} kbit/s): lower the rate"
    return f"{need}, {baud} baud carries {baud / 1000:.1f} kbit/s: use --baud {slowest}"


def decay_bits_per_second(rate_hz: float) -> float:
    """Serial bits per second of the decay output set at ``rate_hz`` (8N1)."""
    return frame_bytes_per_second(decay_output_configuration(int(rate_hz)), rate_hz) * BITS_PER_BYTE


def is_600_series(product_code: str) -> bool:
    """MTi 600-series (MTi-610/620/630/670/680...): they set baud rates with PortConfig, not SetBaudrate."""
    return re.match(r"MTi-6\d0", product_code) is not None


def port_config_payload(words: Sequence[int], rate: int) -> bytes:
    """SetPortConfig data: the device's port words with the first (host) port's baud code set to ``rate``.

    One U32 per port, the baud code in the low byte, the other bits (flow control, stop bits,
    parity) kept as the device reported them [inference from xspublic ``XsPortConfig``].
    """
    if not words:
        raise ProtocolError("the device reported no ports in its port configuration")
    first = (words[0] & ~0xFF) | baud_code(rate)
    return struct.pack(f">{len(words)}I", first, *words[1:])


def parse_port_config(payload: bytes) -> list[int]:
    """Port words of a ReqPortConfig reply (one U32 per port)."""
    if not payload or len(payload) % 4:
        raise ProtocolError(f"port configuration of {len(payload)} bytes is not whole 4-byte words")
    return list(struct.unpack(f">{len(payload) // 4}I", payload))


def port_config_baud(words: Sequence[int]) -> int:
    """The first port's rate in bit/s."""
    code = words[0] & 0xFF
    if code not in BAUD_CODES:
        raise ProtocolError(f"port configuration baud code 0x{code:02X} is not a known code")
    return BAUD_CODES[code]


def baudrate_payload(rate: int) -> bytes:
    """SetBaudrate data (one code byte); the new rate applies after a reset."""
    return bytes((baud_code(rate),))


def parse_baudrate(payload: bytes) -> int:
    """Rate in bit/s from a ReqBaudrate ack."""
    if len(payload) != 1 or payload[0] not in BAUD_CODES:
        raise ProtocolError(f"baud-rate reply {payload.hex(' ') or '(empty)'} is not one known code byte")
    return BAUD_CODES[payload[0]]


def parse_fw_rev(payload: bytes) -> str:
    """Firmware revision text: 'major.minor.rev' (legacy 3 bytes) plus ' build B scm S' (11 bytes)."""
    if len(payload) == 3:
        return "{}.{}.{}".format(*payload)
    if len(payload) == 11:
        major, minor, rev, build, scm = struct.unpack(">3BII", payload)
        return f"{major}.{minor}.{rev} build {build} scm {scm}"
    raise ProtocolError(f"firmware revision reply of {len(payload)} bytes (expected 3 or 11)")


def parse_device_id(payload: bytes) -> int:
    """Device id from a DeviceID reply (4 bytes on 1/10/100-series and legacy, 8 on 600-series)."""
    if len(payload) not in (4, 8):
        raise ProtocolError(f"device id reply of {len(payload)} bytes (expected 4 or 8)")
    return int.from_bytes(payload, "big")


def parse_product_code(payload: bytes) -> str:
    """Product code text such as 'MTi-G-710-2A8G4' (NUL and space padded on the wire)."""
    try:
        return bytes(payload).rstrip(b"\x00 ").decode("ascii")
    except UnicodeDecodeError:
        raise ProtocolError(f"product code {payload.hex(' ')} is not ASCII") from None


def parse_error(payload: bytes) -> tuple[int, str]:
    """(code, meaning) of a device Error message."""
    if not payload:
        raise ProtocolError("device error message without an error code")
    return payload[0], error_name(payload[0])


def fw_rev_payload(text: str) -> bytes:
    """The FWRev reply that ``parse_fw_rev`` reads as ``text`` ('2.4.6' or '1.8.2 build 35 scm 0')."""
    match = re.fullmatch(r"(\d+)\.(\d+)\.(\d+)(?: build (\d+) scm (\d+))?", text.strip())
    if match is None:
        raise ProtocolError(f"firmware revision {text!r} is not 'major.minor.rev [build B scm S]'")
    major, minor, rev, build, scm = match.groups()
    if build is None:
        return bytes((int(major), int(minor), int(rev)))
    return struct.pack(">3BII", int(major), int(minor), int(rev), int(build), int(scm))


def device_id_payload(device_id: int, family_600: bool = False) -> bytes:
    """The DeviceID reply: 8 bytes on a 600-series, 4 on the others (``parse_device_id`` reads both)."""
    return device_id.to_bytes(8 if family_600 else 4, "big")
