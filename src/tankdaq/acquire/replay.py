"""Replay a recording as it happened: re-decode the raw bytes, re-detect, re-identify, re-show.

The raw channel is fed, chunk by chunk with its arrival time, through the same
stream decoder and the same pipeline as the live daemon without its recording sink
(the live fit and the view), so the viewer shows what it showed live. ``speed`` paces by device time
(1.0 = real time); ``None`` runs as fast as possible. What a person is told goes to ``listeners``
as typed events (``acquire.events``), as the daemon's does.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ..device.decoding import SampleDecoder
from ..device.driver import StreamBlock
from ..device.legacy_output import LegacyOutput
from ..errors import BadRecordingInput, InputError
from ..live.preparation import prepare_identifier
from ..records import DecayEnd
from ..store.reader import read_recording, truncation_notice
from ..viz.live import LiveView
from ..viz.view_process import View
from ..viz.viewer import default_viewer_mode, describe_mode
from ..viz.web_view import WebLiveView
from ..viz.web_viewer import WebServer, is_web
from .decay import LiveFit
from .events import DecayOutcome, Event, Notice, ViewerNote
from .live_panel import LivePanel
from .pipeline import DecayPipeline, DetectionSettings
from .sinks import Sink, ViewSink

#: At full speed, serial reads are merged into blocks spanning this much arrival time: the
#: per-block work is shared and the result is the same (the decoder is a stream decoder).
COALESCE_S = 0.25


def coalesce(chunks: list[tuple[int, bytes]], span_s: float) -> list[tuple[int, bytes]]:
    """Merge consecutive ``(host ns, bytes)`` reads spanning at most ``span_s`` (stamped with the last)."""
    if span_s <= 0:
        return list(chunks)
    merged: list[tuple[int, bytes]] = []
    parts: list[bytes] = []
    first_ns = last_ns = 0
    for host_ns, raw in chunks:
        if parts and host_ns - first_ns > span_s * 1e9:
            merged.append((last_ns, b"".join(parts)))
            parts = []
        if not parts:
            first_ns = host_ns
        parts.append(raw)
        last_ns = host_ns
    if parts:
        merged.append((last_ns, b"".join(parts)))
    return merged


def replay_views(mode: str, axis: str, web: WebServer | None, note: Callable[[str], None]) -> list[View]:
    """The replay's views: the one ``mode`` names, or with a web viewer's server the web's (the
    operator's panel: the release angle against the nominal), and beside it the saving one (web+save)."""
    if is_web(mode) and web is None:
        raise InputError("viewer mode web needs the web viewer's server: start a viz.web_viewer.WebServer")
    if web is None:
        return [LiveView(mode, axis=axis, on_note=note)]
    views: list[View] = [
        WebLiveView(web.stream.url, recording_id=web.stream.recording_id, axis=axis, on_note=note)
    ]
    return views + ([LiveView("save", axis=axis, on_note=note)] if mode == "web+save" else [])


def replay_recording(
    path: str | Path,
    speed: float | None = None,
    viewer: str | None = "none",
    model: str | None = None,
    listeners: Sequence[Sink] = (),
    on_progress: Callable[[int, int], None] | None = None,
    web: WebServer | None = None,
) -> list[DecayOutcome]:
    """Replay one tankdaq MCAP; returns the decays found (normally the one it holds). ``listeners`` hear
    the events (the printer, a collector) and ride along the pipeline. ``web``: with ``--viewer web``,
    the web viewer's server (started by the caller, for every file), the view streams to it."""

    def emit(event: Event) -> None:  # before the pipeline runs: the listeners only
        for listener in listeners:
            listener.on_event(event)

    path = Path(path)
    recording = read_recording(path)
    if recording.truncated:
        emit(Notice("replay", truncation_notice(path, recording.damage)))
    meta = recording.metadata
    axis = recording.axis
    nominal = float(meta.get("angle_nominal_deg", "nan"))
    chunks = coalesce(recording.raw_chunks, COALESCE_S if speed is None else 0.0)
    if not chunks:
        raise BadRecordingInput(f"{path}: the recording holds no raw device bytes to replay")
    mode = viewer or default_viewer_mode()
    emit(ViewerNote(describe_mode(mode, default=viewer is None)))
    views = replay_views(mode, axis, web, lambda line: emit(ViewerNote(line)))
    settings = DetectionSettings(
        axis=axis,
        angle_deg=nominal if math.isfinite(nominal) else 0.0,
        angle_tolerance_deg=math.inf if not math.isfinite(nominal) else 1.0,
        model=model or str(meta.get("model", meta.get("model_terms", "ittc-quadratic-restoring"))),
    )
    prepare_identifier(settings.model, lambda text: emit(Notice("identifier", text)))
    rrd_base = path.with_name(path.stem + ".replay")  # for a view that saves (spawn without a display too)
    # the daemon's pipeline without the recording; each block's refit is done before the next block
    sinks: list[Sink] = [ViewSink(v, rrd_base if v.mode == "save" else None) for v in views]
    sinks += [LivePanel(v, axis, settings.angle_deg) for v in views if isinstance(v, WebLiveView)]
    sinks += listeners
    pipeline = DecayPipeline(settings, sinks, fit=LiveFit(wait_for_fits=True))
    legacy = str(meta.get("legacy_protocol", "false")).lower() == "true"
    rate_hz = float(meta.get("sample_rate_hz", "100"))
    output = LegacyOutput.for_decay(rate_hz) if legacy else None  # as the driver asked for
    decoder = SampleDecoder.for_recording(meta, output)
    wall0: float | None = None
    t0 = 0.0

    def feed(samples: np.ndarray, raw: bytes, host_t: float, carried: int) -> None:
        pipeline.feed(StreamBlock(samples, raw, host_t, min(carried, samples.size)))

    try:
        for i, (host_ns, raw) in enumerate(chunks):
            samples, decoded = decoder.feed(raw, host_ns / 1e9)
            if speed is not None and samples.size:
                if wall0 is None:
                    wall0, t0 = time.monotonic(), float(samples["t"][0])
                due = wall0 + (float(samples["t"][-1]) - t0) / speed
                time.sleep(max(0.0, due - time.monotonic()))
            feed(samples, raw, host_ns / 1e9, decoded.carried)
            if on_progress is not None:
                on_progress(i + 1, len(chunks))
        # the file's last frame, held by the decoder for a successor that never comes (live, the quiet line
        # after it confirmed it): without it a replay ended one sample short of the recording
        end_t = chunks[-1][0] / 1e9
        samples, decoded = decoder.finish(end_t)
        if samples.size:
            feed(samples, b"", end_t, decoded.carried)
        pipeline.abort(DecayEnd.STREAM_ENDED, "end of recording")
    except KeyboardInterrupt:
        pipeline.abort(DecayEnd.STOPPED, "replay stopped by the operator")
        raise
    finally:
        pipeline.close()  # the view (and a decay cut by an error)
    return list(pipeline.outcomes)
