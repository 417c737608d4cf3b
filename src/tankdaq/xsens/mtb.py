"""MT Manager ``.mtb`` logs: back-to-back Xbus frames, as MT Manager and the Xsens SDK write them.

A log starts with the device's Configuration message (0x0D: the master device id, the sampling period,
the date and time the log was started, then per device its id, filter profile and firmware; xspublic
``xsdeviceconfiguration.c``), then eMTS (0x91, extended length), then MTData2 (0x36). An Awinda station
logs several devices, told apart by the frame's bus id (1-N; a single device's data come as the master,
0xFF). A file is not a live line: every bus id is a frame to keep (``framer.ANY_BID``), frames up to
xspublic's limit are accepted, and messages tankdaq does not read (eMTS, 0x98, 0x8B, ...) are skipped and
counted by id, never as corruption. ``decode_log`` gives one ``DecodedBlock`` per device. Pure: no I/O.
"""

from __future__ import annotations

import struct
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from .column_decoder import ORIENTATION_COLUMNS, DecodedBlock, decode_capture
from .constants import MASTER_BID, MID
from .frame import Frame
from .framer import ANY_BID
from .mtdata2 import FRAME_MASK, FRAME_NAMES, FRAMES
from .orientation import euler_from_matrix, quaternion, rotation_matrix
from .timebase import CounterTracker

#: Largest frame data in a log (xspublic ``XS_MAXDATALEN``): an Awinda eMTS is longer than a live frame.
LOG_MAX_DATA_LENGTH = 8185
#: Where the master block's fields are (xspublic ``XsDeviceConfiguration_readFromMessage``).
_MASTER_SIZE = 98
_DEVICE_SIZE = 20
_EMTS = 0x91
#: Earth frame -> ENU, per frame an orientation may be logged in: vectors in ENU are ``M.T @ v`` (the
#: local frame turned as MT Manager's RotLocal turns it; the sensor frame stays, MTi User Manual §NED/NWU).
_TO_ENU = {
    FRAMES["NED"]: np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T,
    FRAMES["NWU"]: np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T,
}
#: Each orientation output from (roll, pitch, yaw) in rad, as it goes on the wire.
_FROM_EULER = {
    "EulerAngles": lambda r, p, y: np.degrees(np.stack((r, p, y), axis=-1)),
    "Quaternion": quaternion,
    "RotationMatrix": rotation_matrix,
}


@dataclass(frozen=True)
class LoggedDevice:
    """One device of a log's Configuration message."""

    bus_id: int  # 1-N, its position in the message; a single device's data also come as the master
    device_id: int
    filter_profile: int
    firmware: str  # major.minor.revision


@dataclass(frozen=True)
class LogConfiguration:
    """The Configuration message (0x0D) a log starts with."""

    master_id: int
    sampling_period: int  # 1/115200 s; newer firmware leaves 0 (the rate comes from SampleTimeFine)
    date: str  # as logged, 8 ASCII characters (``YYYYMMDD``)
    time: str  # as logged, 8 ASCII characters (``HHMMSSss``)
    product_code: str  # newer firmware; empty where the field holds the sampling period
    devices: tuple[LoggedDevice, ...]

    def device(self, bus_id: int) -> LoggedDevice | None:
        """The device that sends as ``bus_id`` (the master bus id: the only device, or the master's)."""
        if bus_id == MASTER_BID:
            return next((d for d in self.devices if d.device_id == self.master_id), None) or (
                self.devices[0] if len(self.devices) == 1 else None
            )
        return next((d for d in self.devices if d.bus_id == bus_id), None)

    def metadata(self, bus_id: int) -> dict[str, object]:
        """What a run of device ``bus_id`` keeps of the log's header (device id as hex, as labels show it)."""
        meta: dict[str, object] = {
            "log_master_id": f"{self.master_id:08X}",
            "log_date": self.date,
            "log_time": self.time,
            "log_sampling_period": self.sampling_period,
        }
        if self.product_code:
            meta["product_code"] = self.product_code
        found = self.device(bus_id)
        if found is not None:
            meta.update(device_id=f"{found.device_id:08X}", firmware=found.firmware,
                        filter_profile=found.filter_profile)  # fmt: skip
        return meta


def _ascii(raw: bytes) -> str:
    """A fixed-width text field: printable characters up to the first NUL."""
    text = raw.split(b"\0", 1)[0].decode("ascii", "replace")
    return "".join(c for c in text if c.isprintable()).strip()


def parse_configuration(payload: bytes) -> LogConfiguration:
    """A Configuration message, read liberally: a short one is read as far as it goes (never raises)."""
    data = payload.ljust(_MASTER_SIZE, b"\0")
    master_id, period = struct.unpack_from(">IH", data, 0)
    product = _ascii(data[32:52])
    product = product if product.startswith("MT") else ""  # an old device keeps other bytes there
    count = min(struct.unpack_from(">H", data, 96)[0], (len(data) - _MASTER_SIZE) // _DEVICE_SIZE)
    devices = []
    for index in range(count):
        at = _MASTER_SIZE + index * _DEVICE_SIZE
        device_id, = struct.unpack_from(">I", data, at)  # fmt: skip
        profile, major, minor, revision = struct.unpack_from(">HBBB", data, at + 12)
        devices.append(LoggedDevice(index + 1, device_id, profile, f"{major}.{minor}.{revision}"))
    return LogConfiguration(
        master_id, period, _ascii(data[16:24]), _ascii(data[24:32]), product, tuple(devices)
    )


def configuration_payload(configuration: LogConfiguration) -> bytes:
    """The Configuration message's data for ``configuration`` (as a device sends it at power-up)."""
    head = bytearray(_MASTER_SIZE)
    struct.pack_into(">IH", head, 0, configuration.master_id, configuration.sampling_period)
    head[16:24] = configuration.date.encode("ascii")[:8].ljust(8, b"\0")
    head[24:32] = configuration.time.encode("ascii")[:8].ljust(8, b"\0")
    head[32:52] = configuration.product_code.encode("ascii")[:20].ljust(20, b"\0")
    struct.pack_into(">H", head, 96, len(configuration.devices))
    for device in configuration.devices:
        entry = bytearray(_DEVICE_SIZE)
        struct.pack_into(">I", entry, 0, device.device_id)
        major, minor, revision = (int(part) for part in device.firmware.split("."))
        struct.pack_into(">HBBB", entry, 12, device.filter_profile, major, minor, revision)
        head += entry
    return bytes(head)


@dataclass
class DecodedLog:
    """A log decoded: its Configuration (None: the log has none), the whole decode, one block per bus id
    that sent MTData2 (in order of bus id), and the frames not read, counted by message id."""

    configuration: LogConfiguration | None
    whole: DecodedBlock
    devices: dict[int, DecodedBlock] = field(default_factory=dict)
    not_read: Counter[int] = field(default_factory=Counter)

    def device_label(self, bus_id: int) -> str:
        """How a device is named to people: its device id where the Configuration gives it."""
        found = self.configuration.device(bus_id) if self.configuration else None
        bus = "master" if bus_id == MASTER_BID else f"bus {bus_id}"
        return f"{found.device_id:08X} ({bus})" if found else bus

    def summary(self) -> str:
        """One line: the messages per device, what was skipped by message id, and the real damage."""
        per_device = ", ".join(
            f"{self.device_label(b)}: {block.n_messages}{_lost(block)}" for b, block in self.devices.items()
        )
        parts = [f"{self.whole.n_messages} MTData2 messages of {len(self.devices)} device(s) ({per_device})"]
        if not self.devices:
            parts = ["no MTData2 messages"]
        if self.not_read:
            skipped = ", ".join(f"{_mid_name(mid)} x{n}" for mid, n in sorted(self.not_read.items()))
            parts.append(f"skipped {sum(self.not_read.values())} messages not read ({skipped})")
        parts.append(f"{self.whole.bad_checksums} bad checksums, {self.whole.skipped_bytes} skipped bytes")
        if self.whole.malformed:
            parts.append(f"{self.whole.malformed} malformed MTData2 messages")
        if self.whole.pending_bytes:
            parts.append(f"{self.whole.pending_bytes} bytes of a cut last frame")
        return "; ".join(parts)


def orientation_in_enu(block: DecodedBlock) -> str | None:
    """Turn the orientation a device logged in NED or NWU into ENU, in place (the frame tankdaq reads:
    ``column_decoder.to_samples`` leaves any other out); the line that says so, None when all was ENU.
    Roll and pitch are the same in NWU (a turn about the vertical); NED's local frame is turned back to
    ENU."""
    turned: Counter[str] = Counter()
    for name, to_rad in ORIENTATION_COLUMNS.items():
        if name not in block.xdis:
            continue
        frames = block.xdis[name] & FRAME_MASK
        for bits, to_enu in _TO_ENU.items():
            rows = np.flatnonzero(block.present[name] & (frames == bits))
            if not rows.size:
                continue
            euler = to_rad(block.columns[name][rows])
            wire = rotation_matrix(euler[:, 0], euler[:, 1], euler[:, 2])  # column by column
            matrix = to_enu @ wire.reshape(-1, 3, 3).transpose(0, 2, 1)
            enu = euler_from_matrix(matrix.transpose(0, 2, 1).reshape(-1, 9))
            block.columns[name][rows] = _FROM_EULER[name](enu[:, 0], enu[:, 1], enu[:, 2])
            block.xdis[name][rows] &= ~FRAME_MASK
            turned[FRAME_NAMES[bits]] += rows.size
    if not turned:
        return None
    said = ", ".join(f"{count} in {frame}" for frame, count in sorted(turned.items()))
    return f"orientation logged in another earth frame turned to ENU ({said}): roll and pitch as in ENU"


def _lost(block: DecodedBlock) -> str:
    """The packets a device's PacketCounter says are missing, as the summary says it ("" for none)."""
    if "PacketCounter" not in block.columns:
        return ""
    tracker = CounterTracker()
    tracker.update_many(block.columns["PacketCounter"][block.present["PacketCounter"]].astype(np.int64))
    return f" ({tracker.lost} packets lost)" if tracker.lost else ""


def _mid_name(mid: int) -> str:
    """A message id as the summary names it: its name where tankdaq knows it, else its hex value."""
    return "eMTS 0x91" if mid == _EMTS else Frame(0, mid, b"").name


def decode_log(data: bytes) -> DecodedLog:
    """Every frame of a log, any bus id (``split_log``)."""
    return split_log(decode_capture(data, LOG_MAX_DATA_LENGTH, bids=ANY_BID))


def split_log(whole: DecodedBlock) -> DecodedLog:
    """A log's decode (decoded with ``bids=ANY_BID``): MTData2 split by the device that sent it, the first
    Configuration read, every other message counted by id (never as corruption)."""
    configuration = None
    not_read: Counter[int] = Counter()
    for frame in whole.other_frames:
        if frame.mid == MID.CONFIGURATION and configuration is None:
            configuration = parse_configuration(frame.payload)
        else:
            not_read[frame.mid] += 1
    buses = np.unique(whole.bus_ids).tolist()
    devices = {int(bus): whole.take(np.flatnonzero(whole.bus_ids == bus)) for bus in buses}
    return DecodedLog(configuration, whole, devices, not_read)
