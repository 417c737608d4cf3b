"""``tankdaq predict``: roll damping predicted from a hull's particulars (simplified Ikeda; docs/ikeda.md)."""

from __future__ import annotations

import json
import math
from typing import Annotated

import typer

from ..config import validation
from .app import app, checked, draft_option, handles_errors
from .options import FullScale, JsonOutput, SeaTemperature, WaterTemperature

#: Amplitudes shown when no --angle is given (deg): the band a decay test covers.
DEFAULT_ANGLES_DEG = (5.0, 10.0, 15.0, 20.0)
#: The smallest amplitude predicted (deg): ITTC ends a decay at 0.5 deg; far below, the friction
#: formula's laminar C_F grows without bound.
MIN_AMPLITUDE_DEG = 0.1


def roll_amplitude_deg(value: float) -> float:
    """A roll amplitude to predict at: a release angle (up to 45 deg) of at least ``MIN_AMPLITUDE_DEG``."""
    from ..errors import InputError

    if not (math.isfinite(value) and MIN_AMPLITUDE_DEG <= value <= validation.MAX_RELEASE_ANGLE_DEG):
        raise InputError(
            f"--angle {value:g}: give a roll amplitude of {MIN_AMPLITUDE_DEG:g} to "
            f"{validation.MAX_RELEASE_ANGLE_DEG:g} deg"
        )
    return float(value)


@app.command("predict")
@handles_errors
def predict_command(
    hull: Annotated[
        str, typer.Option("--hull", help="Hull name or .toml with [particulars] (docs/hulls.md).")
    ],
    draft: float = draft_option(),
    speed: Annotated[
        float | None,
        typer.Option("--speed", help="Carriage speed, m/s (default: the hull's speed_m_s, else 0)."),
    ] = None,
    angles_deg: Annotated[
        list[float] | None,
        typer.Option("--angle", callback=checked(roll_amplitude_deg), help="Roll amplitude, deg (repeat)."),
    ] = None,
    period: Annotated[
        float | None,
        typer.Option("--period", help="Roll period, s (default: from GM, gyradius and added inertia)."),
    ] = None,
    full_scale: FullScale = False,
    water_temperature: WaterTemperature = None,
    sea_temperature: SeaTemperature = None,
    as_json: JsonOutput = False,
) -> None:
    """Predict the roll damping components at the natural roll frequency (simplified Ikeda method)."""
    from ..config.hulls import WaterSettings, friction_scaling, full_scale_of, ikeda_prediction, load_hull
    from ..errors import InputError
    from ..physics.friction_scaling import correct_prediction
    from ..physics.ikeda import summary_lines

    if speed is not None and not (math.isfinite(speed) and speed >= 0):
        raise InputError(f"--speed {speed:g} must be zero or a positive speed in m/s")
    if period is not None and not (math.isfinite(period) and period > 0):
        raise InputError(f"--period {period:g} must be a positive roll period in s")
    loaded = load_hull(hull)
    scale = full_scale_of(loaded, full_scale)
    water = WaterSettings(water_temperature, sea_temperature)
    known = "speed_m_s" in loaded.main_particulars.at(draft)
    said = "--speed" if speed is not None else "the hull's speed_m_s" if known else "assumed: no speed given"
    if speed is None:
        speed = loaded.main_particulars.at(draft).get("speed_m_s", 0.0)
    prediction = ikeda_prediction(loaded, draft, speed, period)
    amplitudes = [math.radians(a) for a in sorted(set(angles_deg or DEFAULT_ANGLES_DEG))]
    summary = {"hull": loaded.name, "draft_factor": draft, **prediction.summary(amplitudes, scale)}
    if scale is not None:  # the ship's friction at its own Reynolds number (ITTC 7.5-02-07-04.5)
        correct_prediction(summary, friction_scaling(loaded, draft, scale, speed, water, said))
    if as_json:
        typer.echo(json.dumps(summary))
        return
    typer.echo(f"hull {loaded.name}, draft factor {draft:g}, speed {speed:g} m/s: simplified Ikeda")
    for line in summary_lines(summary):
        typer.echo(line)
