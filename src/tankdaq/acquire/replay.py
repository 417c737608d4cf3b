"""Replay a recording as it happened: re-decode the raw bytes, re-detect, re-identify, re-show.

The raw channel is fed, chunk by chunk with its arrival time, through the same
stream decoder and the same ``DecaySession`` as the live daemon (with writing
off), so the viewer shows what it showed live. ``speed`` paces by device time
(1.0 = real time); ``None`` runs as fast as possible.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

from ..errors import BadRecordingInput
from ..store.reader import iter_raw_chunks, read_recording
from ..viz.live import LiveView
from ..xsens.batch import to_samples
from ..xsens.stream import StreamDecoder
from ..xsens.timebase import SampleTimeUnwrapper
from .session import Block, DecayOutcome, DecaySession, SessionSettings


def replay_recording(
    path: str | Path,
    speed: float | None = None,
    viewer: str = "none",
    model: str | None = None,
    on_event: Callable[[str], None] | None = None,
    on_progress: Callable[[int, int], None] | None = None,
) -> list[DecayOutcome]:
    """Replay one tankdaq MCAP; returns the decays found (normally the one it holds)."""
    path = Path(path)
    recording = read_recording(path)
    meta = recording.metadata
    if str(meta.get("legacy_protocol", "False")) == "True":
        raise BadRecordingInput(
            f"{path}: replay of legacy MTData recordings is not supported yet; use identify"
        )
    axis = recording.axis
    nominal = float(meta.get("angle_nominal_deg", "nan"))
    settings = SessionSettings(
        axis=axis,
        angle_deg=nominal if math.isfinite(nominal) else 0.0,
        angle_tolerance_deg=math.inf if not math.isfinite(nominal) else 1.0,
        model=model or str(meta.get("model_terms", "ittc-quadratic-restoring")),
        out_dir=None,
        rrd_base=path.with_name(path.stem + ".replay") if viewer == "save" else None,
    )
    view = LiveView(viewer, axis=axis)
    session = DecaySession(settings, view, on_event=on_event)
    decoder = StreamDecoder()
    unwrapper = SampleTimeUnwrapper()
    chunks = list(iter_raw_chunks(path))
    if not chunks:
        raise BadRecordingInput(f"{path}: the recording holds no raw device bytes to replay")
    wall0: float | None = None
    t0 = 0.0
    for i, (host_ns, raw) in enumerate(chunks):
        samples = to_samples(decoder.feed(raw), unwrapper, host_ns / 1e9)
        if speed is not None and samples.size:
            if wall0 is None:
                wall0, t0 = time.monotonic(), float(samples["t"][0])
            due = wall0 + (float(samples["t"][-1]) - t0) / speed
            time.sleep(max(0.0, due - time.monotonic()))
        session.feed(Block(samples, raw, host_ns / 1e9))
        if on_progress is not None:
            on_progress(i + 1, len(chunks))
    session.abort("note", "end of recording")
    view.close()
    return session.outcomes
