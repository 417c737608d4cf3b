"""Serial bytes to samples, MTData2 or legacy MTData: one decoder for the driver and for replay.

The driver feeds what it reads from the port; replay feeds the raw channel of a recording.
Both must turn the same bytes into the same samples, so the code that does it lives once, here.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import ProtocolError
from ..samples import empty_samples
from ..xsens.column_decoder import DecodedBlock, to_samples
from ..xsens.constants import MID
from ..xsens.control import INTEGRATED_RATE_OF_TURN
from ..xsens.legacy import decode_mtdata
from ..xsens.stream_decoder import StreamDecoder
from ..xsens.timebase import MODULUS_ONE_DAY, TICKS_PER_SECOND, SampleTimeUnwrapper, sample_time_modulus
from .attitude import GyroAttitude
from .legacy_output import LegacyOutput

#: How well a recording's gyro bias is known when its file is decoded again (rad/s).
KNOWN_BIAS_SD_RAD_S = 1e-4


class SampleDecoder:
    """``feed(raw, host_t)`` -> (``SAMPLE_DTYPE`` samples, the decoded block with its other frames).

    MTData2: device time from unwrapped SampleTimeFine (``modulus`` of the device family).
    Legacy (``legacy`` given): time is the unwrapped sample counter times the output period.
    ``integrated``: the device gives no orientation (IMU-class): roll and pitch of every sample
    come from its rate of turn, anchored by gravity while quiet (``attitude.GyroAttitude``).
    """

    def __init__(
        self,
        legacy: LegacyOutput | None = None,
        modulus: int = MODULUS_ONE_DAY,
        integrated: bool = False,
        attitude: GyroAttitude | None = None,
    ) -> None:
        self.legacy = legacy
        self.attitude = attitude or (GyroAttitude() if integrated else None)
        self.stream = StreamDecoder()
        self._unwrapper = SampleTimeUnwrapper(modulus)
        self._legacy_counter = SampleTimeUnwrapper(1 << 16)

    @classmethod
    def for_device(
        cls, product_code: str, legacy: LegacyOutput | None = None, integrated: bool = False
    ) -> SampleDecoder:
        """The decoder for the device that says it is ``product_code``: its family's clock modulus.

        Make one per session and feed it every block: its unwrapper carries each wrap of
        SampleTimeFine from the session's first sample on.
        """
        return cls(legacy, sample_time_modulus(product_code), integrated)

    @classmethod
    def for_recording(
        cls, metadata: Mapping[str, object], legacy: LegacyOutput | None = None
    ) -> SampleDecoder:
        """The decoder for the device a recording's metadata describe: its product's clock modulus,
        and roll and pitch integrated again when the device gave no orientation (an IMU-class device),
        from the gyro bias the recorder had learnt (a file begins in the hold: too short to learn it)."""
        modulus = sample_time_modulus(str(metadata.get("product_code", "")))
        if metadata.get("orientation_source") != INTEGRATED_RATE_OF_TURN:
            return cls(legacy, modulus)
        try:
            bias = (float(str(metadata["gyro_bias_p_rad_s"])), float(str(metadata["gyro_bias_q_rad_s"])))
        except (KeyError, ValueError):
            return cls(legacy, modulus, integrated=True)  # a file cut before it closed: learnt again
        known = GyroAttitude(initial_bias_rad_s=bias, initial_bias_sd_rad_s=KNOWN_BIAS_SD_RAD_S)
        return cls(legacy, modulus, attitude=known)

    def attitude_metadata(self) -> dict[str, object]:
        """What a recording of an integrated attitude keeps at close: the gyro bias learnt (none: {})."""
        if self.attitude is None:
            return {}
        bias_p, bias_q = self.attitude.bias_rad_s
        return {"gyro_bias_p_rad_s": bias_p, "gyro_bias_q_rad_s": bias_q}

    def feed(self, raw: bytes, host_t: float) -> tuple[np.ndarray, DecodedBlock]:
        """Samples completed by ``raw``; an empty read (a quiet line) confirms a held frame."""
        decoded = self.stream.feed(raw) if raw else self.stream.flush()
        if self.legacy is None:
            samples = to_samples(decoded, self._unwrapper, host_t)
            if self.attitude is not None:
                self.attitude.fill(samples)
            return samples, decoded
        return self._legacy_samples(decoded, host_t), decoded

    def finish(self, host_t: float) -> tuple[np.ndarray, DecodedBlock]:
        """The stream ended (a device gone): samples of the frames held (``StreamDecoder.finish``)."""
        decoded = self.stream.finish()
        if self.legacy is None:
            return to_samples(decoded, self._unwrapper, host_t), decoded
        return self._legacy_samples(decoded, host_t), decoded

    def _legacy_samples(self, decoded: DecodedBlock, host_t: float) -> np.ndarray:
        output = self.legacy
        assert output is not None
        rows = []
        for frame in decoded.other_frames:
            if frame.mid != MID.MTDATA:
                continue
            try:
                rows.append(decode_mtdata(frame.payload, output.mode, output.settings))
            except ProtocolError:  # a frame that does not fit the layout is counted, not fatal
                self.stream.malformed += 1
        out = empty_samples(len(rows))
        if not rows:
            return out
        counters = np.array([r["PacketCounter"] for r in rows])
        counts = self._legacy_counter.update_many(counters)
        out["ticks"] = np.round(counts * (TICKS_PER_SECOND / output.rate_hz)).astype(np.int64)
        out["t"] = out["ticks"] / TICKS_PER_SECOND
        out["host_t"] = host_t
        out["counter"] = counters
        columns = {"EulerAngles": ("roll", "pitch", "yaw"), "RateOfTurn": ("p", "q", "r"),
                   "Acceleration": ("ax", "ay", "az")}  # fmt: skip
        for block, names in columns.items():
            values = np.array([r[block] for r in rows], dtype=float)
            if block == "EulerAngles":
                values = np.radians(values)
            for column, name in enumerate(names):
                out[name] = values[:, column]
        out["status"] = [r.get("StatusByte", 0) for r in rows]
        return out
