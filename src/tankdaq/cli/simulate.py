"""``tankdaq simulate``: a simulated MTi-G on a pseudo-terminal, for trying tankdaq without a sensor."""

from __future__ import annotations

import json
import signal
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from ..config import validation
from ..errors import InputError
from .app import app, checked, draft_option, err_console, handles_errors
from .options import DecayAxis

if TYPE_CHECKING:
    from ..device.simulator import SimulatedMTi
    from ..physics.scenario import DecayScenario


def _free_link(path: Path) -> Path:
    """``--link``: a writable place where nothing is but, at most, a dead simulator's link (never a
    file of the user's: the simulator would replace it, then delete it on exit)."""
    from ..device.simulator.pty_link import link_refusal

    validation.output_file(path, option="--link")
    why = link_refusal(path)
    if why is not None:
        raise InputError(f"--link {why}")
    return path


@app.command("simulate")
@handles_errors
def simulate_command(
    hull: str = typer.Option("swath", "--hull", help="Hull config whose decay model plays (tankdaq hulls)."),
    draft: float = draft_option(),
    angle_deg: float = typer.Option(
        8.0,
        "--angle",
        callback=checked(validation.release_angle_deg),
        help="Tilt angle (deg) the engineer sets by hand.",
    ),
    axis: DecayAxis = "roll",
    rate_hz: float = typer.Option(
        100,
        "--rate",
        callback=checked(validation.output_rate_hz),
        help=f"Output rate the scenario is prepared at (Hz): {validation.OUTPUT_RATES_TEXT}.",
    ),
    seed: int | None = typer.Option(
        None,
        "--seed",
        min=0,
        help="Seed (default: a new one each run, said here and in --truth); the same "
        "seed plays the same test.",
    ),
    runs: int = typer.Option(3, "--runs", min=0, help="Decay runs before the water stays still."),
    release_after_s: float = typer.Option(10.0, "--release-after", help="Seconds from run start to release."),
    decay_s: float = typer.Option(25.0, "--decay", help="Seconds of free decay per run."),
    legacy: bool = typer.Option(False, "--legacy", help="Be a 2007-era MTi-G (legacy MTData 0x32)."),
    faults: str = typer.Option(
        "",
        "--faults",
        help="e.g. corrupt=0.001,drop=1e-4,stall=2@30,unplug=60,replug=5,latency=16 (USB bursts every 16 ms)",
    ),
    truth: Path = typer.Option(
        None,
        "--truth",
        callback=checked(validation.new_file, option="--truth"),
        help="Write the true release instants and model here (JSON; a new file).",
    ),
    speed: float = typer.Option(1.0, "--speed", help="Play the device clock this many times faster."),
    baud: int = typer.Option(
        115200, "--baud", callback=checked(validation.baud_rate), help="Device baud rate."
    ),
    link: Path = typer.Option(
        None,
        "--link",
        callback=checked(_free_link),
        help="Stable symlink to the pty (default: a temporary path); never put over an existing file.",
    ),
    stuck: bool = typer.Option(False, "--stuck", help="Measuring, ignoring GoToConfig until a Reset."),
    boot_s: float = typer.Option(0.0, "--boot", min=0.0, help="Seconds of silence after a Reset."),
    flash_write_s: float = typer.Option(0.0, "--flash-write", min=0.0, help="Seconds a flash write takes."),
    mti_600: bool = typer.Option(False, "--mti-600", help="Be an MTi-630 (baud rate through PortConfig)."),
    imu: bool = typer.Option(
        False, "--imu", help="Be an MTi-100 IMU: rate of turn and acceleration, no orientation output."
    ),
    refuse: str = typer.Option(
        "", "--refuse", help="Orientation outputs to refuse with Error 0x21: euler, euler,quaternion, ..."
    ),
    sway: bool = typer.Option(
        False, "--sway", help="The hand sways as it holds (0.15 deg at 0.9 Hz + 0.05 deg at 2.3 Hz)."
    ),
    replay: Path = typer.Option(
        None,
        "--replay",
        help="Play the device of this recording (its /xsens/raw bytes at their pace), not a scripted decay.",
    ),
) -> None:
    """Serve a simulated MTi-G on a pty; the first stdout line is the port to open."""
    from ..config.hulls import format_draft, hull_scenario, load_hull
    from ..device.simulator import (
        Behaviour,
        DeviceIdentity,
        Faults,
        ScriptedSource,
        SimulatedMTi,
        refused_orientation,
    )
    from ..device.simulator.playback import recorded_device
    from ..physics.scenario import Handling, fresh_seed
    from ..physics.sensor import SensorNoise

    if speed <= 0:
        raise InputError(f"--speed must be positive, got {speed:g}")
    hull_config = load_hull(hull)
    validation.hull_draft(hull_config, draft, axis)
    if legacy and mti_600:
        raise InputError("--legacy and --mti-600 exclude each other: a 600-series device speaks MTData2")
    if replay is not None and (legacy or truth is not None):
        raise InputError("--replay plays the recorded MTData2 as it was: no --legacy, no scripted --truth")
    refuses = refused_orientation(refuse)
    if (imu or refuses) and (legacy or mti_600 or replay is not None):
        raise InputError(
            "--imu and --refuse play an MTData2 device of their own: no --legacy, --mti-600 or --replay"
        )
    seed = fresh_seed(seed)
    scenario = hull_scenario(
        hull_config, draft, axis, angle_deg=angle_deg, rate_hz=rate_hz, runs=runs, seed=seed,
        release_after_s=release_after_s, decay_s=decay_s, handling=Handling.swaying() if sway else Handling(),
        noise=SensorNoise.mti_100() if imu else SensorNoise(),  # an IMU's gyro and accelerometer
    )  # fmt: skip
    fault_set = Faults.parse(faults)
    source = recorded_device(replay) if replay is not None else ScriptedSource(scenario)
    playing = (
        f"playing the device of {replay}"
        if replay is not None
        else f"{hull} {format_draft(draft)} {axis} {angle_deg:g} deg, {runs} runs, seed {seed}"
    )
    sim = SimulatedMTi(
        source=source,
        speed=speed,
        legacy=legacy,
        baud=baud,
        faults=fault_set,
        link=None if link is None else str(link),
        seed=seed,
        behaviour=Behaviour(stuck=stuck, flash_write_s=flash_write_s, boot_s=boot_s, refuses=refuses),
        identity=DeviceIdentity.mti_630() if mti_600 else DeviceIdentity.mti_100() if imu else None,
    )
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    with sim:
        if truth is not None:
            _write_truth(truth, sim, scenario)
        typer.echo(sim.link)
        sys.stdout.flush()  # the first line is read by whoever started us, before we ever exit
        err_console.print(
            f"simulated {sim.identity.product_code} on {sim.port} (link {sim.link}), {baud} baud, "
            f"{playing}, speed x{speed:g}; Ctrl-C stops",
            markup=False,
            highlight=False,
        )
        err_console.print(
            f"for --port auto and re-plugs elsewhere: export TANKDAQ_SERIAL_BY_ID={sim.by_id_dir}",
            markup=False,
            highlight=False,
        )
        with err_console.status("serving") as status:
            while not stop.wait(0.5):
                state = "measuring" if sim.measuring else "config" if sim.plugged else "unplugged"
                status.update(
                    f"device time {sim.device_time():.0f} s, {state}, {sim.frames_sent} frames sent"
                )
    err_console.print(f"stopped after {sim.frames_sent} frames", markup=False, highlight=False)


def _write_truth(path: Path, sim: SimulatedMTi, scenario: DecayScenario) -> None:
    """The truth file: every run's release (s from power-up, SampleTimeFine), initial state, model."""
    from ..config.hulls import format_draft

    document = {
        "hull": scenario.hull,
        "draft": format_draft(scenario.draft),
        "axis": scenario.axis,
        "angle_deg": scenario.angle_deg,
        "rate_hz": scenario.rate_hz,
        "seed": scenario.seed,
        "start_ticks": sim.start_ticks,
        "note": "release_s counts from power-up; release_index is at rate_hz (at other rates use the ticks)",
        "runs": [run.to_json() for run in sim.truth],
    }
    from ..store.safe_write import write_text_new

    write_text_new(path, json.dumps(document, indent=2) + "\n")
