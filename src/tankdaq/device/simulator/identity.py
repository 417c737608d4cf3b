"""Who the simulated device says it is: device id, product code, firmware revision."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ...errors import ProtocolError
from ...xsens.control import fw_rev_payload, is_600_series, is_imu_class
from ...xsens.timebase import sample_time_modulus


@dataclass(frozen=True)
class DeviceIdentity:
    """What the device says about itself."""

    device_id: int
    product_code: str
    firmware: bytes  # raw ReqFWRev payload (11 bytes MkIV+, 3 bytes legacy)

    @classmethod
    def mti_g_710(cls) -> DeviceIdentity:
        return cls(0x077B1A2C, "MTi-G-710-2A8G4", fw_rev_payload("1.8.2 build 35 scm 0"))

    @classmethod
    def legacy_mti_g(cls) -> DeviceIdentity:
        """The public ethz issue #66 device: a 2007-era MTi-G (Mark III)."""
        return cls(0x01500618, "MTi-G-28A53G35", fw_rev_payload("2.4.6"))

    @classmethod
    def mti_630(cls) -> DeviceIdentity:
        """A 600-series unit: 8-byte device id, baud rate through PortConfig."""
        return cls(0x0880_0000_0000_1A2C, "MTi-630-2A8G4", fw_rev_payload("1.12.0 build 100 scm 0"))

    @classmethod
    def mti_100(cls) -> DeviceIdentity:
        """An IMU-class unit: rate of turn and acceleration, no orientation output [device id type
        0x0067 for an MTi-100 is an inference]."""
        return cls(0x00671A2C, "MTi-100-2A8G4", fw_rev_payload("1.8.2 build 35 scm 0"))

    @property
    def serial_number(self) -> str:
        """The USB serial number (Xsens put the device id there)."""
        return f"{self.device_id:08X}"

    @property
    def family_600(self) -> bool:
        return is_600_series(self.product_code)

    @property
    def imu_class(self) -> bool:
        """No orientation output: the device refuses Euler angles, quaternion and rotation matrix."""
        return is_imu_class(self.product_code)

    @property
    def clock_modulus(self) -> int:
        """Where this device's SampleTimeFine wraps (one day on the 10/100-series, 2**32 on a 600)."""
        return sample_time_modulus(self.product_code)

    @classmethod
    def recorded(cls, device: Mapping[str, Any]) -> DeviceIdentity | None:
        """The identity a recording's device settings give (None when they are not all there)."""
        try:
            firmware = fw_rev_payload(str(device["firmware"]))
            return cls(int(device["device_id"]), str(device["product_code"]), firmware)
        except (KeyError, TypeError, ValueError, ProtocolError):
            return None
