"""Faults of a tank's serial line, switched on from the start or from Python while the device runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError


@dataclass(frozen=True)
class Faults:
    """Faults switched on from the start (rates per byte; times in device seconds, -1 = never)."""

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    stall_at_s: float = -1.0
    stall_s: float = 0.0
    unplug_at_s: float = -1.0
    replug_after_s: float = -1.0

    @classmethod
    def parse(cls, text: str) -> Faults:
        """``corrupt=1e-3,drop=1e-4,stall=2@30,unplug=60,replug=5`` (stall S seconds at T)."""
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
                else:
                    raise ValueError(key)
            except ValueError:
                example = "corrupt=0.001,drop=1e-4,stall=2@30,unplug=60,replug=5"
                raise InputError(f"fault {part!r} not understood; write e.g. {example}") from None
        faults = cls(**values)
        if not (0 <= faults.corrupt_rate < 1 and 0 <= faults.drop_rate < 1):
            raise InputError("corrupt and drop rates are fractions of bytes between 0 and 1")
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
