"""``tankdaq device ...``: the device tools a lab otherwise opens MT Manager for."""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer

from .app import app, err_console, handles_errors

if TYPE_CHECKING:
    from ..device.driver import MTiDriver

device_app = typer.Typer(
    no_args_is_help=True,
    help="Find, inspect, reset and restore Xsens MTi devices (PORT may be 'auto': the one Xsens device).",
)
app.add_typer(device_app, name="device")

PORT_ARGUMENT = typer.Argument(..., help="Device path, pyserial URL, or 'auto' (the one Xsens device).")
BAUD_OPTION = typer.Option(
    115200, "--baud", help="Look for the device at this rate first (the other standard rates follow)."
)


def _driver(port: str, baud: int) -> MTiDriver:
    """The driver, imported here: ``tankdaq --help`` stays fast."""
    from ..device.driver import MTiDriver

    return MTiDriver(port, probe_first=baud)


@device_app.command("ports")
@handles_errors
def ports_command() -> None:
    """List the serial ports: USB vendor:product, description, and which are Xsens devices or FTDI cables."""
    from ..device.ports import list_serial_ports

    entries = list_serial_ports()
    if not entries:
        err_console.print("no serial ports (is the USB cable in? is the xsens_mt / ftdi_sio driver loaded?)")
        raise typer.Exit(1)
    typer.echo(f"{'port':24s} {'kind':10s} {'vid:pid':9s} description")
    for entry in entries:
        typer.echo(entry.line())


@device_app.command("info")
@handles_errors
def info_command(port: str = PORT_ARGUMENT, baud: int = BAUD_OPTION) -> None:
    """Hand-shake; print device id, product, firmware, baud rate, output configuration (changes nothing)."""
    with _driver(port, baud) as driver:
        report = driver.inspect()
    for line in report.lines():
        typer.echo(line)


@device_app.command("reset")
@handles_errors
def reset_command(port: str = PORT_ARGUMENT, baud: int = BAUD_OPTION) -> None:
    """Reset the device (it reboots and measures with its stored settings)."""
    with _driver(port, baud) as driver:
        woke = driver.reset_device()
    typer.echo(f"reset {driver.path}: {'rebooted (WakeUp seen)' if woke else 'reset sent, no WakeUp seen'}")


@device_app.command("restore-defaults")
@handles_errors
def restore_defaults_command(
    port: str = PORT_ARGUMENT,
    baud: int = BAUD_OPTION,
    yes: bool = typer.Option(False, "--yes", help="Do not ask for confirmation (scripts)."),
) -> None:
    """RestoreFactoryDefaults, then Reset: outputs, filter and baud rate (115200) as shipped."""
    question = f"restore the factory defaults of the device on {port}? (output and baud settings are lost)"
    if not yes and not typer.confirm(question):
        err_console.print("nothing changed", markup=False)
        raise typer.Exit(1)
    with _driver(port, baud) as driver:
        woke = driver.reset_device(restore_defaults=True)
    state = "rebooted (WakeUp seen)" if woke else "reset sent, no WakeUp seen"
    typer.echo(f"factory defaults restored on {driver.path}: {state}; it now runs at 115200 baud")
