"""The simulated MTi's MTData2 frames, made a block at a time with numpy, are byte for byte those of the
reference encoders frame by frame (``build_frame(MID.MTDATA2, encode_mtdata2(items))``): every output the
simulator sends, every precision and frame its XDI allows, slower outputs at divided rates, SampleTimeFine
past the clock's modulus, the packet counter past 65535, the extended length, and the errors the reference
raises for values it refuses."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tankdaq.device.simulator.output import DEVICE_RATES_HZ, SUPPORTED_OUTPUTS, Output, OutputItem
from tankdaq.errors import ProtocolError
from tankdaq.physics.truth import TICK_MODULUS
from tankdaq.samples import SAMPLE_DTYPE
from tankdaq.xsens.constants import MID
from tankdaq.xsens.control import MAX_FREQUENCY, PER_MESSAGE_OUTPUTS
from tankdaq.xsens.frame import build_frame
from tankdaq.xsens.mtdata2 import encode_mtdata2, make_xdi, spec_for
from tankdaq.xsens.orientation import quaternion, rotation_matrix

#: Every form the simulator's outputs can be asked in: (name, precision, frame).
FORMS = [
    (name, precision, frame)
    for name in sorted(SUPPORTED_OUTPUTS)
    for precision in spec_for(name).precisions()
    for frame in spec_for(name).frames()
]
MODULI = (TICK_MODULUS, 1 << 32)  # an MTi-G-710's day, a 600-series' 32 bits


def _reference_value(
    name: str, sample: np.void, row: int, turned: dict[str, np.ndarray], modulus: int
) -> object:
    """One output's value for ``encode_value``, read off the sample as the wire defines it."""
    if name in turned:
        return turned[name][row].tolist()
    if name in ("EulerAngles", "RateOfTurn", "Acceleration"):
        fields = {"EulerAngles": ("roll", "pitch", "yaw"), "RateOfTurn": ("p", "q", "r")}.get(
            name, ("ax", "ay", "az")
        )
        values = [float(sample[f]) for f in fields]
        return [math.degrees(v) for v in values] if name == "EulerAngles" else values
    ticks, status = int(sample["ticks"]), int(sample["status"])
    wire = {
        "PacketCounter": int(sample["counter"]),
        "SampleTimeFine": ticks % modulus,
        "SampleTimeCoarse": (ticks // 10_000) % (1 << 32),
        "StatusWord": status,
        "StatusByte": status % 256,
    }
    return wire[name]


def reference_frames(output: Output, block: np.ndarray, indices: np.ndarray) -> list[bytes]:
    """Frame by frame through the reference encoders; an output at ``hz`` rides along every
    ``rate / hz``-th frame of the device's grid (per-message outputs in every frame)."""
    turned = {  # the block's orientation in the other two forms, computed on the block as the simulator does
        "Quaternion": quaternion(block["roll"], block["pitch"], block["yaw"]),
        "RotationMatrix": rotation_matrix(block["roll"], block["pitch"], block["yaw"]),
    }
    frames = []
    for row, (sample, k) in enumerate(zip(block, indices.tolist(), strict=True)):
        items = [
            (item.xdi, _reference_value(item.name, sample, row, turned, output.clock_modulus))
            for item in output.items
            if item.hz == MAX_FREQUENCY or k % max(1, round(output.rate_hz / item.hz)) == 0
        ]
        frames.append(build_frame(MID.MTDATA2, encode_mtdata2(items)))
    return frames


def samples(n: int, *, seed: int, scale: float, modulus: int, rate_hz: float) -> np.ndarray:
    """``n`` samples whose SampleTimeFine passes ``modulus`` and whose counter passes 65535 mid-block."""
    rng = np.random.default_rng(seed)
    block = np.zeros(n, SAMPLE_DTYPE)
    for field in ("roll", "pitch", "yaw", "p", "q", "r", "ax", "ay", "az"):
        block[field] = rng.normal(scale=scale, size=n)
    step = round(10_000 / rate_hz)
    block["ticks"] = modulus - step * (n // 2) + step * np.arange(n)
    block["counter"] = (65536 - n // 3 + np.arange(n)) % 65536
    block["status"] = rng.integers(0, 1 << 32, n, dtype=np.uint64)
    return block


def outcome(encode: Callable[[], list[bytes]]) -> list[bytes] | str:
    """The frames, or the error the encoder raised (both paths must raise the same)."""
    try:
        return encode()
    except (ProtocolError, ValueError, OverflowError) as exc:
        return f"{type(exc).__name__}: {exc}"


def assert_same_frames(output: Output, block: np.ndarray, first: int = 0) -> list[bytes] | str:
    indices = np.arange(first, first + block.size)
    made = outcome(lambda: output.encode(block, indices))
    assert made == outcome(lambda: reference_frames(output, block, indices))
    return made


def item(name: str, precision: str = "float32", frame: str = "ENU", hz: int = 100) -> OutputItem:
    return OutputItem(make_xdi(name, precision, frame), MAX_FREQUENCY if name in PER_MESSAGE_OUTPUTS else hz)


@pytest.mark.parametrize(("name", "precision", "frame"), FORMS)
def test_every_output_in_every_form_at_full_and_divided_rates(name: str, precision: str, frame: str) -> None:
    for modulus in MODULI:
        output = Output(
            items=[item("PacketCounter"), item(name, precision, frame, hz=100), item("Acceleration", hz=400)],
            clock_modulus=modulus,
        )
        block = samples(41, seed=len(FORMS), scale=1.0, modulus=modulus, rate_hz=400)
        frames = assert_same_frames(output, block, first=3)
        assert isinstance(frames, list) and len(frames) == 41
        sizes = {len(frame_) for frame_ in frames}
        assert len(sizes) == (1 if name in PER_MESSAGE_OUTPUTS else 2)  # the 100 Hz output every 4th frame


@settings(max_examples=60, deadline=None)
@given(
    forms=st.lists(st.sampled_from(FORMS), min_size=1, max_size=8),
    rates=st.lists(st.sampled_from(DEVICE_RATES_HZ), min_size=8, max_size=8),
    n=st.integers(0, 48),
    first=st.integers(0, 10**6),
    modulus=st.sampled_from(MODULI),
    seed=st.integers(0, 2**32 - 1),
    scale=st.sampled_from([1e-3, 1.0, 40.0]),  # 40 rad: Euler angles beyond FP12.20's 2048 deg
)
def test_random_blocks_and_configurations_give_the_reference_bytes(
    forms: list[tuple[str, str, str]],
    rates: list[int],
    n: int,
    first: int,
    modulus: int,
    seed: int,
    scale: float,
) -> None:
    output = Output(
        items=[item(*form, hz=hz) for form, hz in zip(forms, rates, strict=False)], clock_modulus=modulus
    )
    block = samples(n, seed=seed, scale=scale, modulus=modulus, rate_hz=output.rate_hz)
    assert_same_frames(output, block, first)


def test_a_payload_past_254_bytes_takes_the_extended_length_and_past_2048_the_reference_error() -> None:
    matrix = item("RotationMatrix", "float64", hz=100)  # 75 bytes an item
    block = samples(9, seed=1, scale=1.0, modulus=TICK_MODULUS, rate_hz=100)
    frames = assert_same_frames(Output(items=[item("PacketCounter"), matrix, matrix, matrix, matrix]), block)
    assert isinstance(frames, list) and {frame[3] for frame in frames} == {0xFF}  # FA FF 36 FF LENH LENL
    refused = assert_same_frames(Output(items=[matrix] * 28), block)
    assert isinstance(refused, str) and refused.startswith("ProtocolError")


def test_a_device_told_to_send_nothing_sends_empty_messages() -> None:
    frames = assert_same_frames(
        Output(items=[]), samples(3, seed=3, scale=1.0, modulus=TICK_MODULUS, rate_hz=100)
    )
    assert frames == [bytes.fromhex("FA FF 36 00 CB")] * 3


def test_values_the_reference_refuses_or_packs_its_own_way_give_its_bytes_or_its_error() -> None:
    block = samples(8, seed=2, scale=1.0, modulus=TICK_MODULUS, rate_hz=100)
    block["roll"][2], block["p"][5], block["ax"][6] = np.nan, np.inf, 1e39  # float32 overflows: refused
    for precision in ("float32", "fp1220", "fp1632", "float64"):
        for name in ("EulerAngles", "RateOfTurn", "Acceleration", "Quaternion"):
            assert_same_frames(Output(items=[item("PacketCounter"), item(name, precision)]), block)
    refused = (("RateOfTurn", "fp1220"), ("Acceleration", "fp1632"), ("Acceleration", "float32"))
    errors = [assert_same_frames(Output(items=[item(name, precision)]), block) for name, precision in refused]
    assert all(isinstance(error, str) for error in errors)  # round(inf), out of FP16.32, 1e39 as float32
