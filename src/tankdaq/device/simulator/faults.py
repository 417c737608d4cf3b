"""Faults of a tank's serial line, switched on from the start or from Python while the device runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError


@dataclass(frozen=True)
class Faults:
    """Faults switched on from the start (rates per byte; times in device seconds, -1 = never).

    ``latency_ms``: a USB serial adapter's latency timer (FTDI's default is 16 ms): the bytes are held
    and handed to the host in one burst every ``latency_ms`` of wall time, as an FTDI chip does with a
    stream that does not fill its buffer; 0 delivers them as the line carries them.
    """

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    stall_at_s: float = -1.0
    stall_s: float = 0.0
    unplug_at_s: float = -1.0
    replug_after_s: float = -1.0
    latency_ms: float = 0.0

    @classmethod
    def parse(cls, text: str) -> Faults:
        """``corrupt=1e-3,drop=1e-4,stall=2@30,unplug=60,replug=5,latency=16`` (stall S seconds at T;
        latency: USB bursts every so many ms)."""
        values: dict[str, float] = {}
        for part in filter(None, (p.strip() for p in text.split(","))):
            key, _, value = part.partition("=")
            try:
                if key == "stall":
                    seconds, _, at = value.partition("@")
                    values["stall_s"], values["stall_at_s"] = float(seconds), float(at or 0.0)
                elif key in ("corrupt", "drop"):
                    values[f"{key}_rate"] = float(value)
                elif key == "unplug":
                    values["unplug_at_s"] = float(value)
                elif key == "replug":
                    values["replug_after_s"] = float(value)
                elif key == "latency":
                    values["latency_ms"] = float(value)
                else:
                    raise ValueError(key)
            except ValueError:
                example = "corrupt=0.001,drop=1e-4,stall=2@30,unplug=60,replug=5,latency=16"
                raise InputError(f"fault {part!r} not understood; write e.g. {example}") from None
        faults = cls(**values)
        if not (0 <= faults.corrupt_rate < 1 and 0 <= faults.drop_rate < 1):
            raise InputError("corrupt and drop rates are fractions of bytes between 0 and 1")
        if not 0 <= faults.latency_ms <= 255:
            raise InputError("latency is an FTDI latency timer: 0 to 255 ms (16 is the default)")
        return faults

    def inject(self, data: bytes, rng: np.random.Generator) -> tuple[bytes, int, int]:
        """``data`` with bytes corrupted and dropped at the configured rates; (data, corrupted, dropped)."""
        if not (self.corrupt_rate or self.drop_rate) or not data:
            return data, 0, 0
        arr = np.frombuffer(data, dtype=np.uint8).copy()
        corrupted = dropped = 0
        if self.corrupt_rate:
            hit = np.flatnonzero(rng.random(arr.size) < self.corrupt_rate)
            arr[hit] ^= rng.integers(1, 256, hit.size, dtype=np.uint8)
            corrupted = hit.size
        if self.drop_rate:
            keep = rng.random(arr.size) >= self.drop_rate
            dropped = int(arr.size - keep.sum())
            arr = arr[keep]
        return arr.tobytes(), corrupted, dropped
