"""A recording's device, ready to play again: its ``/xsens/raw`` bytes as a simulator source.

The raw channel holds the bytes exactly as the driver read them, so a decay recorded on a real
MTi can be re-sent through the simulator's pty and recorded again through the real driver.
"""

from __future__ import annotations

from pathlib import Path

from ...config.validation import input_file
from ...errors import BadRecordingInput
from ...store.reader import read_recording
from . import DeviceIdentity, RecordedSource


def recorded_device(path: str | Path) -> RecordedSource:
    """The frames of ``path``'s raw channel, with the output configuration and identity of its device."""
    recording = read_recording(input_file(Path(path), "recording", BadRecordingInput))
    raw = b"".join(chunk for _, chunk in recording.raw_chunks)
    if not raw:
        raise BadRecordingInput(f"{path} has no raw device bytes (/xsens/raw) to play")
    if str(recording.metadata.get("legacy_protocol", "false")).lower() == "true":
        raise BadRecordingInput(f"{path} holds legacy MTData: only MTData2 recordings can be played")
    device = recording.run_config.get("device", {})
    return RecordedSource(
        raw, device.get("configuration") or None, name=str(path), identity=DeviceIdentity.recorded(device)
    )
