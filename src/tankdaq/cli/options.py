"""The options several commands share, defined once: the same flag, help and check wherever it appears.

Each is an ``Annotated`` type for a command's signature (``axis: DecayAxis = "roll"``) or, where the
help differs by command, a function giving the ``typer.Option``. Checks are ``tankdaq.config.validation``
rules run while the arguments are parsed (``app.checked``): one ``error:`` line and exit 2 before any work.
``--draft`` is ``app.draft_option``; ``--catalogue`` and ``--runs`` are ``app.catalogue_option`` and
``app.runs_option``, typed here.
"""

from __future__ import annotations

from typing import Annotated, Any

import typer

from ..config import validation
from .app import catalogue_option, checked, runs_option

# The run catalogue (identify, campaign, diagnose): where fits are written, and --runs in place of paths.
CatalogueOption = Annotated[str | None, catalogue_option()]
RunsQuery = Annotated[str | None, runs_option()]

#: ``--axis`` of a command that tilts or reads one axis (roll by default).
DecayAxis = Annotated[
    str, typer.Option("--axis", callback=checked(validation.decay_axis), help="roll or pitch.")
]
#: ``--axis`` of a command whose recordings say their axis (identify): given, or the files'.
ReadAxis = Annotated[
    str | None,
    typer.Option(
        "--axis",
        callback=checked(validation.decay_axis),
        help="roll or pitch (default: a recording's own axis; roll for CSV).",
    ),
]
#: ``--json``: the result as JSON on stdout (lines and progress stay on stderr).
JsonOutput = Annotated[bool, typer.Option("--json", help="Print the result as JSON on stdout.")]

# How other labs' CSV files are read (identify, diagnose: ``tankdaq.Reading``).
TimeColumn = Annotated[
    str, typer.Option("--time-col", help="Time column of a CSV, HDF5, .mat or Parquet file.")
]
AngleColumn = Annotated[str, typer.Option("--angle-col", help="Angle column of such a file.")]
RateColumn = Annotated[
    str, typer.Option("--rate-col", help="Rate column of such a file (ignored when absent).")
]
AngleUnit = Annotated[
    str | None,
    typer.Option(
        "--angle-unit",
        callback=checked(validation.angle_unit),
        help="Unit of the file's angle and rate: deg or rad [default: from the data].",
    ),
]
TimeUnit = Annotated[
    str | None,
    typer.Option(
        "--time-unit",
        callback=checked(validation.time_unit),
        help="Unit of the CSV time: s, ms or tick (0.1 ms: an Xsens SampleTimeFine) [default: the data].",
    ),
]
SampleRate = Annotated[
    float | None,
    typer.Option(
        "--rate",
        min=0.1,
        max=100_000.0,
        help="Sample rate, Hz, of a text export that does not say it (MT Manager 2019.2+ without "
        "SampleTimeFine) [default: the file's].",
    ),
]
#: ``--device``: one device of an MT Manager log that holds several (an Awinda station's MTw sensors).
LogDevice = Annotated[
    str | None,
    typer.Option("--device", help="Device of an MT Manager .mtb log: id (hex) or bus id [default: each]."),
]
#: ``--speed-col``: a carriage-speed column (m/s) of a CSV, HDF5 or TDMS file; each decay's speed.
SpeedColumn = Annotated[
    str | None,
    typer.Option("--speed-col", help="Carriage-speed column (m/s), e.g. GROUP/CHANNEL of a TDMS file."),
]
KeepAll = Annotated[bool, typer.Option("--keep-all", help="Do not cut the CSV record at the release.")]
SkipHalfCycles = Annotated[
    int, typer.Option("--skip-half-cycles", min=0, help="Half-cycles dropped after it.")
]
# Where the free decay is taken from and to (identify, diagnose, campaign); automatic end by default.
StartS = Annotated[
    float | None, typer.Option("--start", min=0.0, help="Keep from S s after each release (default 0).")
]
EndS = Annotated[
    float | None,
    typer.Option("--end", min=0.0, help="End each free decay S s after its release (default: found)."),
]
#: ``--full-scale`` (identify, campaign): the ship's results by Froude from the hull's scale factor.
FullScale = Annotated[
    bool,
    typer.Option(
        "--full-scale",
        help="Also report at full scale (the hull's scale_factor): Froude and friction-corrected (ITTC).",
    ),
]


def _water_temperature(flag: str, whose: str) -> Any:
    """``--water-temperature`` / ``--sea-temperature`` (identify, campaign): the water of ``--full-scale``'s
    friction correction, degC, checked 0-40 while parsed; else the hull's keys, else 15 degC."""
    return typer.Option(
        flag,
        callback=checked(validation.water_temperature_c, option=flag),
        help=f"{whose} temperature, degC, for --full-scale's friction [default: the hull's, else 15].",
    )


WaterTemperature = Annotated[float | None, _water_temperature("--water-temperature", "Tank water")]
SeaTemperature = Annotated[float | None, _water_temperature("--sea-temperature", "The ship's sea water")]


def report_option(help: str) -> Any:
    """``--report DIR`` (campaign, diagnose): a folder checked writable while the arguments are parsed
    (the report's own names are checked free by the library, before any work); the help says the rule."""
    return typer.Option(
        "--report",
        callback=checked(validation.output_dir, option="--report"),
        help=f"{help} Existing files are never overwritten: a report whose file is there is refused "
        "before any work (move it first).",
    )


def model_option(
    help: str = "auto (the data choose, as every command does for the same decays), terms (b1,b2,c1,c3) "
    "or an alias (docs/models.md).",
) -> Any:
    """``--model`` of the commands that fit (checked by the library before any file is read)."""
    return typer.Option("--model", help=help)
