"""Structured fuzzing of the decoders (issue 11): how many of 2,000 random MTData2 messages raise.

The issue's probe crashed 683 of 2,000 structured inputs (a UtcTime of zeros: ``year 0 is out of
range``). Here 2,000 messages are built from a seeded generator as the probe built them: one to
eight items with identifiers tankdaq knows (any precision and frame bits), random payloads of the
right size (3 % of any size), a third of the UtcTime items zeros (as before a GNSS fix). Each
goes through the per-message decoder and everything a command does with a value (JSON, the decode
command's CSV columns), and the whole stream through the driver's sample decoder.

Counted: messages refused on purpose (ProtocolError: sizes that do not fit the identifier), and
any other exception (a crash). The baseline, measured in the same run on the same inputs, is how
many decoded messages hold a UtcTime that the old ``isoformat`` (``datetime(year, ...)``) raised on.

    .venv/bin/python bench/bench_decoder_fuzz.py [--messages 2000] [--seed 11]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from datetime import UTC, datetime

import numpy as np

from benchjson import write_result
from tankdaq.cli.decode import flatten
from tankdaq.device.decoding import SampleDecoder
from tankdaq.errors import ProtocolError
from tankdaq.xsens.constants import MID
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.mtdata2 import (
    DATA_SPECS,
    TYPE_MASK,
    UTC_STRUCT,
    UtcTime,
    decode_mtdata2,
    item_size,
    to_jsonable,
)


def random_message(rng: np.random.Generator) -> bytes:
    """One MTData2 payload of 1-8 known items with random payloads and sizes."""
    items = []
    for _ in range(int(rng.integers(1, 9))):
        spec = DATA_SPECS[int(rng.integers(len(DATA_SPECS)))]
        xdi = (spec.base & TYPE_MASK) | int(rng.integers(16))
        expected = item_size(spec, xdi)
        choice = rng.random()
        if spec.kind == "utc" and choice < 1 / 3:
            payload = UTC_STRUCT.pack(0, 0, 0, 0, 0, 0, 0, 0)
        elif expected is not None and choice < 0.97:
            payload = rng.bytes(expected)
        else:  # a size that may not fit the identifier: the message is refused on purpose
            payload = rng.bytes(int(rng.integers(0, 61)))
        items.append(xdi.to_bytes(2, "big") + bytes([len(payload)]) + payload)
    return b"".join(items)


def old_isoformat_raises(value: object) -> bool:
    """What the pre-fix ``UtcTime.isoformat`` did: build a datetime from the fields."""
    if not isinstance(value, UtcTime):
        return False
    try:
        datetime(value.year, value.month, value.day, value.hour, value.minute, value.second, tzinfo=UTC)
    except ValueError:
        return True
    return False


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    payloads = [random_message(rng) for _ in range(args.messages)]

    refused = crashed = baseline_crashes = 0
    started = time.perf_counter()
    for payload in payloads:
        try:
            message = decode_mtdata2(payload)
        except ProtocolError:
            refused += 1
            continue
        baseline_crashes += any(old_isoformat_raises(v) for v in message.values())
        try:
            for name, value in message.items():
                json.dumps(to_jsonable(value))
                flatten(name, value)
        except Exception:
            crashed += 1
    per_message_s = time.perf_counter() - started

    stream = b"".join(build_frame(MID.MTDATA2, payload) for payload in payloads)
    started = time.perf_counter()
    try:
        samples, block = SampleDecoder().feed(stream, 0.0)
        stream_crash = "none"
    except Exception as exc:
        samples, block, stream_crash = None, None, f"{type(exc).__name__}: {exc}"
    stream_s = time.perf_counter() - started

    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"{args.messages} structured random MTData2 messages (seed {args.seed})")
    print(f"  refused on purpose (ProtocolError): {refused}")
    print(f"  decoded: {args.messages - refused}")
    print(f"  crashed now (any other exception in decode, JSON, CSV columns): {crashed}")
    print(f"  baseline, same inputs: would have crashed the old isoformat: {baseline_crashes}")
    rate = args.messages / per_message_s
    print(f"  per-message path: {per_message_s * 1e3:.0f} ms ({rate:,.0f} messages/s)")
    frames = block.frames if block is not None else 0
    kept = samples.size if samples is not None else 0
    print(
        f"  stream path (SampleDecoder, {frames} frames, {kept} samples): crash {stream_crash}, "
        f"{stream_s * 1e3:.1f} ms"
    )
    write_result(
        "decoder_fuzz",
        "structured random MTData2 messages through the per-message decoder, JSON and the CSV columns, and "
        "the whole stream through the driver's sample decoder: refused on purpose, crashed, speed",
        counts={"messages": args.messages, "seed": args.seed},
        figures={
            "refused": refused,
            "crashed": crashed,
            "stream_crashed": stream_crash != "none",
            "baseline_isoformat_crashes": baseline_crashes,
            "per_message_messages_per_s": rate,
            "stream_ms": stream_s * 1e3,
        },
        baseline="the old isoformat on the same decoded messages, same run",
    )


if __name__ == "__main__":
    main()
