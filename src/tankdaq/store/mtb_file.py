"""Decays from MT Manager ``.mtb`` logs (the raw Xbus log MT Manager and the Xsens SDK write).

The bytes are decoded by ``xsens.mtb`` (any bus id, the Configuration message read, messages tankdaq does
not read counted by id); each device's MTData2 messages become samples as a live recording's do
(``xsens.column_decoder.to_samples``: time from SampleTimeFine, unwrapped at the device family's modulus,
never from the Configuration's sampling period, which newer firmware leaves 0), and one record per device
comes back whole, its releases found by ``ident.inputs`` as a CSV's. ``--device ID`` (a device id in hex, or a
bus id) keeps one device of a log that holds several. The log's header (device id, firmware, filter
profile, date and time) is each run's metadata, and what was read and skipped is said in one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config.validation import input_file
from ..errors import BadIdentificationInput, InputError
from ..records import DecayRun
from ..samples import AXIS_FIELDS
from ..xsens.column_decoder import to_samples
from ..xsens.mtb import DecodedLog, decode_log, orientation_in_enu
from ..xsens.timebase import MODULUS_32_BIT, MODULUS_ONE_DAY, SampleTimeUnwrapper, sample_time_modulus
from .csv_import import FIND_RELEASES, MIN_SAMPLES, NOTICES, CsvOptions


def read_mtb(path: Path, axis: str | None, options: CsvOptions) -> list[DecayRun]:
    """One record per device of the log (or the one ``options.device`` names), each whole."""
    input_file(path, "MT Manager log (.mtb)")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror}") from None
    log = decode_log(data)
    if not log.devices:
        raise BadIdentificationInput(
            f"{path}: no MTData2 message in {len(data)} bytes ({log.summary()}): is it an MT Manager log?"
        )
    axis = axis or "roll"
    runs, refused = [], []
    for bus_id in _chosen(path, log, options.device):
        try:
            runs.append(_device_run(path, log, bus_id, axis, several=len(log.devices) > 1))
        except BadIdentificationInput as exc:  # a station's own messages, a device without orientation
            refused.append(str(exc))
    if not runs:
        raise BadIdentificationInput("; ".join(refused))
    lines = [f"{path.name}: {log.summary()}", *(f"not read: {line}" for line in refused)]
    for run in runs:
        run.meta[NOTICES] = [*lines, *run.meta.get(NOTICES, ())]
        if not options.keep_all:
            run.meta[FIND_RELEASES] = True
    return runs


def _chosen(path: Path, log: DecodedLog, device: str | None) -> list[int]:
    """The bus ids to read: every device's, or the one ``device`` names (a hex device id or a bus id)."""
    if device is None:
        return list(log.devices)
    wanted = device.strip().upper().removeprefix("0X")
    for bus_id in log.devices:
        found = log.configuration.device(bus_id) if log.configuration else None
        if (found is not None and wanted == f"{found.device_id:08X}") or wanted == str(bus_id):
            return [bus_id]
    known = ", ".join(log.device_label(bus_id) for bus_id in log.devices)
    raise InputError(f"{path}: no device {device!r} in this log; it holds {known} (give --device with one)")


def _device_run(path: Path, log: DecodedLog, bus_id: int, axis: str, several: bool) -> DecayRun:
    """One device's samples as a record (rows without an orientation or a time are left out, and said)."""
    block = log.devices[bus_id]
    config = log.configuration
    product = config.product_code if config else ""
    ticks = block.columns.get("SampleTimeFine")
    modulus = sample_time_modulus(product)
    if ticks is not None and ticks.size and int(np.nanmax(ticks)) >= MODULUS_ONE_DAY:
        modulus = MODULUS_32_BIT  # a clock beyond one day is a 2**32 family's, whatever the header says
    turned = orientation_in_enu(block)
    samples = to_samples(block, SampleTimeUnwrapper(modulus))
    angle_field, rate_field = AXIS_FIELDS[axis]
    keep = np.isfinite(samples["t"]) & np.isfinite(samples[angle_field])
    label = log.device_label(bus_id)
    if np.count_nonzero(keep) < MIN_SAMPLES:
        raise BadIdentificationInput(
            f"{path}: device {label}: {np.count_nonzero(keep)} samples with a time and an orientation of "
            f"{block.n_messages} messages (it sent {', '.join(block.columns) or 'no outputs'}); a decay "
            f"needs at least {MIN_SAMPLES}"
        )
    kept = samples[keep]
    other = next(name for name in AXIS_FIELDS if name != axis)
    other_angle, other_rate = AXIS_FIELDS[other]
    rate = kept[rate_field] if np.isfinite(kept[rate_field]).all() else None
    meta: dict[str, object] = {"file": str(path), "axis": axis, "bus_id": bus_id}
    meta.update(config.metadata(bus_id) if config else {})
    meta["sample_rate_hz"] = round(float(1.0 / np.median(np.diff(kept["t"]))), 6)
    notices = [f"{path.name}: device {log.device_label(bus_id)}: {turned}"] if turned else []
    if kept.size < samples.size or samples.size < block.n_messages:
        notices.append(
            f"{path.name}: device {label}: {block.n_messages - kept.size} of {block.n_messages} messages not "
            f"samples (no SampleTimeFine or no orientation)"
        )
    meta[NOTICES] = notices
    channels = {f"other_angle_{other}": kept[other_angle], f"other_rate_{other}": kept[other_rate]}
    return DecayRun(
        t=kept["t"],
        angle=kept[angle_field],
        rate=rate,
        axis=axis,
        name=f"{path.stem}@{meta.get('device_id', bus_id)}" if several else path.stem,
        channels={name: values for name, values in channels.items() if np.isfinite(values).all()},
        meta=meta,
    )
