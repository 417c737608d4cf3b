"""The real MTi-G-710 captures in ``shared/data`` (einride/xsens-go testdata) and their reference decodes.

A test asks for one by name (``capture("einride-1")``: its ``output.bin``); where the shared data is not
beside the checkout the test skips and says where it looked. Never copied into the repository.
"""

from __future__ import annotations

from pathlib import Path

import pytest

CAPTURES = Path(__file__).resolve().parents[3] / "shared" / "data" / "xsens-captures"
SETS = [f"einride-{n}" for n in range(1, 6)]

#: einride's spelling -> the Xsens names tankdaq uses.
GOLDEN_NAMES = {
    "UTCTime": "UtcTime",
    "GNSSPVTData": "GnssPvtData",
    "GNSSSatInfo": "GnssSatInfo",
    "PositionECEF": "PositionEcef",
}
GOLDEN_PRECISIONS = {"Float32": "float32", "FP1220": "fp1220", "FP1632": "fp1632", "Float64": "float64"}
GOLDEN_FRAMES = {"EastNorthUp": "ENU", "NorthEastDown": "NED", "NorthWestUp": "NWU"}

Field = tuple[str, str | None, str | None, list[str]]  # name, frame, precision, value lines


def capture_dir(name: str) -> Path:
    """The folder of capture ``name`` (``output.bin``, ``output.golden``, ...); skips the test without it."""
    path = CAPTURES / name
    if not (path / "output.bin").is_file():
        pytest.skip(f"real captures not found at {path} (check out shared/data beside the repository)")
    return path


def capture(name: str) -> Path:
    """The raw bytes of capture ``name`` as the device sent them; skips the test without it."""
    return capture_dir(name) / "output.bin"


def parse_head(head: str) -> tuple[str, str | None, str | None]:
    """'EulerAngles(EastNorthUp,Float32)' -> ('EulerAngles', 'ENU', 'float32')."""
    name, _, rest = head.rstrip(":").partition("(")
    parts = rest.rstrip(")").split(",") if rest else []
    frame = next((GOLDEN_FRAMES[p] for p in parts if p in GOLDEN_FRAMES), None)
    precision = next((GOLDEN_PRECISIONS[p] for p in parts if p in GOLDEN_PRECISIONS), None)
    return GOLDEN_NAMES.get(name, name), frame, precision


def read_golden_blocks(path: Path) -> list[list[Field]]:
    """The reference decode: blank-line separated blocks of 'Name(format):' and indented values."""
    blocks: list[list[Field]] = []
    for text in path.read_text().split("\n\n"):
        fields: list[Field] = []
        for line in text.splitlines():
            if line.startswith("  "):
                fields[-1][3].append(line.strip())
            elif line:
                fields.append((*parse_head(line), []))
        if fields:
            blocks.append(fields)
    return blocks
