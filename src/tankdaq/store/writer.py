"""RecordingWriter: one MCAP file per decay, written so that a killed process or a full disk loses little.

Crash safety comes from the write policy, not from luck: messages collect in an
in-memory MCAP chunk, and the chunk is closed, written and fsync'ed as soon as
its oldest message is half a ``flush_interval_s`` old (the other half covers the
gap until the next write and the fsync itself). A killed writer therefore
loses at most ``flush_interval_s`` of data, and ``tankdaq recover`` rebuilds
the missing summary. Events are flushed at once: a release or an unplug is
worth a small chunk.
"""

from __future__ import annotations

import errno
import json
import os
import time
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, Self, TypeVar

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer

from .._version import __version__
from ..config.hulls import Hull, format_draft
from ..errors import RecordingError
from ..samples import AXIS_FIELDS, SAMPLE_DTYPE
from . import schemas
from .naming import create_exclusive

_DISK_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}
T = TypeVar("T")


class _UnbufferedFile:
    """The minimal stream mcap.Writer needs, writing straight to the fd.

    No Python-side buffer means nothing is held back after a failed write, so a
    full disk can be reported and the file closed without a second failure.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.position = 0

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            written = os.write(self.fd, view)
            self.position += written
            view = view[written:]
        return len(data)

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        """Nothing is buffered here; durability comes from ``os.fsync`` in the writer."""


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def describe_run(
    axis: str,
    angle_nominal_deg: float,
    hull: Hull | None = None,
    draft: float | None = None,
    sample_rate_hz: float | None = None,
    device: Mapping[str, object] | None = None,
    operator: str = "",
    note: str = "",
) -> dict[str, object]:
    """The ``run_metadata`` a recording starts with, under the keys of ``schemas.RUN_METADATA_KEYS``.

    ``device`` holds what the driver read from the instrument (device_id,
    product_code, firmware) and the line it used (baud; baud_changed_from when tankdaq
    moved the device to that rate). Hull dimensions are copied so the file stands alone
    when the hull configuration changes later.
    """
    described: dict[str, object] = {"axis": axis, "angle_nominal_deg": float(angle_nominal_deg)}
    if hull is not None:
        described["hull"] = hull.name
        described["hull_description"] = hull.description
        described.update({f"hull_{key}": value for key, value in hull.dimensions.items()})
    if draft is not None:
        described["draft"] = format_draft(draft)
    if sample_rate_hz is not None:
        described["sample_rate_hz"] = float(sample_rate_hz)
    for key in ("device_id", "product_code", "firmware", "baud"):
        if device and device.get(key) is not None:
            described[key] = device[key]
    if device and device.get("baud") is not None:
        described["baud_changed"] = device.get("baud_changed_from") is not None
        if described["baud_changed"]:
            described["baud_before"] = device["baud_changed_from"]
    if operator:
        described["operator"] = operator
    if note:
        described["note"] = note
    return described


class RecordingWriter:
    """Write one decay recording: raw serial bytes, samples, events and fits, plus run metadata.

    ``path`` is never overwritten (``-2``, ``-3`` ... is added; the final name is
    ``self.path``). ``run_metadata`` goes into the ``tankdaq.run`` metadata record
    at start and, completed, again at close; ``run_config`` is attached as JSON.
    Use as a context manager or call ``close()``. Not thread-safe: one record
    loop owns it, and calls ``maybe_flush()`` on ticks without data.
    """

    def __init__(
        self,
        path: str | Path,
        run_metadata: Mapping[str, object],
        run_config: Mapping[str, object],
        flush_interval_s: float = 1.0,
        chunk_size: int = 256 * 1024,
    ) -> None:
        if flush_interval_s <= 0:
            raise ValueError("flush_interval_s must be positive")
        self.path, fd = create_exclusive(path)
        self.flush_interval_s = flush_interval_s
        self._file = _UnbufferedFile(fd)
        self._closed = False
        self._failed = False
        self._unflushed_since: float | None = None
        self._metadata: dict[str, object] = {
            "software_version": __version__,
            "created_utc": _utc_now(),
            **run_metadata,
        }
        self._axis = str(self._metadata.get("axis", "roll"))
        self._warnings: list[str] = []
        self._release: tuple[float, float] | None = None  # (device t, host epoch s)
        self._block: list[tuple[np.ndarray, np.ndarray]] = []  # (samples, stamps) for the next block
        self._side: list[tuple[str, bytes, int]] = []  # events and fits, written beside the blocks
        self._axis_time: list[np.ndarray] = []
        self._axis_angle: list[np.ndarray] = []
        self.samples_written = 0
        self.raw_bytes_written = 0
        self._mcap = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)  # type: ignore[arg-type]
        try:
            self._guarded(self._start, run_config)
        except RecordingError:
            os.close(fd)  # nobody holds this writer yet, so nobody else could close it
            self._closed = True
            raise

    # -- life cycle -------------------------------------------------------------------------------------

    def _start(self, run_config: Mapping[str, object]) -> None:
        self._mcap.start(profile="", library=f"tankdaq {__version__}")
        self._channels: dict[str, int] = {}
        raw = schemas.TOPIC_RAW  # schemaless (schema id 0): the bytes are the device's own protocol
        self._channels[raw] = self._mcap.register_channel(
            raw, schemas.RAW_MESSAGE_ENCODING, 0, schemas.CHANNEL_METADATA[raw]
        )
        blocks = schemas.TOPIC_SAMPLE_BLOCKS  # schemaless: the dtype is in the channel metadata
        self._channels[blocks] = self._mcap.register_channel(
            blocks, schemas.BLOCK_MESSAGE_ENCODING, 0, schemas.CHANNEL_METADATA[blocks]
        )
        for topic, name, body in (
            (schemas.TOPIC_SAMPLES, "tankdaq.Sample", schemas.SAMPLES_SCHEMA),
            (schemas.TOPIC_EVENTS, "tankdaq.Event", schemas.EVENTS_SCHEMA),
            (schemas.TOPIC_FIT, "tankdaq.Fit", schemas.FIT_SCHEMA),
        ):
            schema_id = self._mcap.register_schema(name, SchemaEncoding.JSONSchema, body)
            self._channels[topic] = self._mcap.register_channel(
                topic, MessageEncoding.JSON, schema_id, schemas.CHANNEL_METADATA[topic]
            )
        now_ns = time.time_ns()
        self._mcap.add_metadata(schemas.RUN_METADATA_NAME, schemas.metadata_strings(self._metadata))
        config = json.dumps(run_config, indent=2, default=str).encode()
        self._mcap.add_attachment(now_ns, now_ns, schemas.CONFIG_ATTACHMENT_NAME, "application/json", config)
        self._sync()

    def close(self) -> None:
        """Write the completed run metadata, the summary and the footer; fsync; close. Idempotent."""
        if self._closed:
            return
        try:
            if not self._failed:
                self._guarded(self._finish)
        finally:
            self._closed = True
            os.close(self._file.fd)

    def _finish(self) -> None:
        self._close_chunks()  # the last samples go before the final metadata, as they happened
        self._mcap.add_metadata(schemas.RUN_METADATA_NAME, schemas.metadata_strings(self.final_metadata()))
        self._mcap.finish()
        os.fsync(self._file.fd)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # -- writing ----------------------------------------------------------------------------------------

    def write_raw(self, data: bytes, host_ns: int | None = None) -> None:
        """Serial bytes exactly as they arrived, stamped with the host arrival time (ns since epoch)."""
        if not data:
            return
        stamp = time.time_ns() if host_ns is None else int(host_ns)
        self._add(schemas.TOPIC_RAW, [bytes(data)], [stamp])
        self.raw_bytes_written += len(data)

    def write_samples(self, samples: np.ndarray) -> None:
        """A SAMPLE_DTYPE array; log time is each sample's host arrival (now, where it is unknown)."""
        if samples.dtype != SAMPLE_DTYPE:
            raise ValueError(f"write_samples takes a SAMPLE_DTYPE array, not {samples.dtype}")
        if samples.size == 0:
            return
        host_ns = samples["host_t"] * 1e9
        known = np.isfinite(host_ns) & (host_ns > 0)
        stamps = np.where(known, host_ns, float(time.time_ns())).astype(np.int64).tolist()
        self._add(schemas.TOPIC_SAMPLES, schemas.samples_to_json(samples), stamps)
        self._block.append((samples.copy(), np.array(stamps, dtype=np.int64)))
        angle_field = AXIS_FIELDS.get(self._axis, AXIS_FIELDS["roll"])[0]
        self._axis_time.append(samples["t"].copy())
        self._axis_angle.append(samples[angle_field].copy())
        self.samples_written += samples.size

    def write_event(
        self,
        kind: str,
        message: str = "",
        t_s: float | None = None,
        data: Mapping[str, object] | None = None,
        host_ns: int | None = None,
    ) -> None:
        """A run event (release, settled, gap, warning, unplug, note); flushed at once."""
        if kind not in schemas.EVENT_KINDS:
            raise ValueError(f"unknown event kind {kind!r}; known: {', '.join(schemas.EVENT_KINDS)}")
        stamp = time.time_ns() if host_ns is None else int(host_ns)
        record = {"t_s": t_s, "kind": kind, "message": message, "data": dict(data or {})}
        self._add(schemas.TOPIC_EVENTS, [json.dumps(record, default=float).encode()], [stamp])
        if kind == schemas.EventKind.WARNING:
            self._warnings.append(message)
        if kind == schemas.EventKind.RELEASE and t_s is not None:
            self._release = (float(t_s), stamp / 1e9)
        self.flush()

    def write_fit(
        self,
        t_s: float,
        coefficients: Mapping[str, float],
        std: Mapping[str, float] | None = None,
        ci95: Mapping[str, object] | None = None,
        r2: float | None = None,
        extra: Mapping[str, object] | None = None,
        host_ns: int | None = None,
    ) -> None:
        """Coefficients as they evolve (``ci95`` per term as [low, high] or a half-width)."""
        record = schemas.fit_record(t_s, coefficients, std, ci95, r2, extra)
        stamp = time.time_ns() if host_ns is None else int(host_ns)
        self._add(schemas.TOPIC_FIT, [json.dumps(record, default=float).encode()], [stamp])

    def update_metadata(self, values: Mapping[str, object]) -> None:
        """Add or change run metadata; it is written with the final ``tankdaq.run`` record at close."""
        self._metadata.update(values)

    def final_metadata(self) -> dict[str, object]:
        """The run metadata completed with what the recording itself measured."""
        final = dict(self._metadata)
        final["closed_utc"] = _utc_now()
        final["samples"] = self.samples_written
        final["raw_bytes"] = self.raw_bytes_written
        final["warnings"] = list(self._warnings)
        if self._axis_time:
            t = np.concatenate(self._axis_time)
            angle = np.concatenate(self._axis_angle)
            if t.size > 1:
                final["duration_s"] = float(t[-1] - t[0])
                final["measured_sample_rate_hz"] = float(1.0 / np.median(np.diff(t)))
            if self._release is not None:
                release_t, release_host_s = self._release
                at_release = np.flatnonzero(t <= release_t)
                final["release_t_s"] = release_t
                release_utc = datetime.fromtimestamp(release_host_s, UTC)
                final["release_utc"] = release_utc.isoformat(timespec="milliseconds")
                if at_release.size and np.isfinite(angle[at_release[-1]]):
                    final["angle_initial_deg"] = float(np.degrees(angle[at_release[-1]]))
        return final

    # -- flushing and errors ----------------------------------------------------------------------------

    def flush(self) -> None:
        """Close the open chunk, write it and fsync: everything written so far survives a kill."""
        self._guarded(self._sync)

    def maybe_flush(self) -> None:
        """Flush if the oldest unflushed data is due; call it on idle ticks when no data arrives."""
        due = self._unflushed_since is not None
        if due and time.monotonic() - self._unflushed_since >= self.flush_interval_s / 2:  # type: ignore[operator]
            self.flush()

    def _sync(self) -> None:
        self._close_chunks()
        os.fsync(self._file.fd)
        self._unflushed_since = None

    def _close_chunks(self) -> None:
        """Close the data chunk, then write events, fits and the sample block in a small chunk of their own.

        A reader that wants samples, events and fits (``read_recording``) then
        opens only the small chunks and skips the per-sample JSON and raw bytes.
        """
        self._mcap.flush()
        for topic, payload, stamp in self._side:
            self._mcap.add_message(self._channels[topic], stamp, payload, stamp)
        if self._block:
            stamps = np.concatenate([stamp for _, stamp in self._block])
            block = schemas.sample_block(np.concatenate([samples for samples, _ in self._block]), stamps)
            channel = self._channels[schemas.TOPIC_SAMPLE_BLOCKS]
            self._mcap.add_message(channel, int(stamps[0]), block, int(stamps[0]))
        self._side, self._block = [], []
        self._mcap.flush()

    def _add(self, topic: str, payloads: list[bytes], stamps: list[int]) -> None:
        if self._failed:
            raise RecordingError(f"{self.path} stopped after a write error; run tankdaq recover {self.path}")
        if self._closed:
            raise RecordingError(f"{self.path} is already closed; start a new recording")
        if topic in (schemas.TOPIC_EVENTS, schemas.TOPIC_FIT):
            self._side += [(topic, payload, stamp) for payload, stamp in zip(payloads, stamps, strict=True)]
        else:
            channel = self._channels[topic]

            def add_all() -> None:
                for payload, stamp in zip(payloads, stamps, strict=True):
                    self._mcap.add_message(channel, stamp, payload, stamp)

            self._guarded(add_all)
        if self._unflushed_since is None:
            self._unflushed_since = time.monotonic()
        self.maybe_flush()

    def _guarded(self, action: Callable[..., T], *args: Any) -> T:
        """Run a write; an OS error stops the recording with a message that says what to do."""
        try:
            return action(*args)
        except OSError as exc:
            self._failed = True
            if exc.errno in _DISK_FULL_ERRNOS:
                raise RecordingError(
                    f"disk full writing {self.path}: {exc.strerror}; "
                    f"free space, then run tankdaq recover {self.path}"
                ) from None
            raise RecordingError(
                f"cannot write {self.path}: {exc.strerror}; run tankdaq recover {self.path}"
            ) from None
