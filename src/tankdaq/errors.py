"""One error type per domain, each carrying a message a person can act on.

The CLI turns any ``TankdaqError`` into a single line on stderr and exits with
``exit_code``: 2 for bad input or usage (wrong flag, unknown hull, missing file,
missing port), 1 for failures at run time (device vanished, disk full).
"""


def install_hint(extra: str) -> str:
    """How to install an optional extra (``postgres``, ``parquet``, ``dask``, ``notebook``), from an
    index and from a clone, as every line that reports it missing says it."""
    return f"pip install 'tankdaq[{extra}]' (from a clone: pip install '.[{extra}]')"


class TankdaqError(Exception):
    """Base of every error tankdaq raises on purpose."""

    exit_code: int = 1


class InputError(TankdaqError):
    """Bad input from the user: a flag value, a file, a hull name. Exit code 2."""

    exit_code = 2


class ConfigError(InputError):
    """A configuration file (hull, vehicle, campaign) is missing or malformed."""


class ProtocolError(TankdaqError):
    """An Xbus message that cannot be built or understood."""


class DeviceError(TankdaqError):
    """The serial device is absent, busy, silent, or answered with an error."""


class DeviceNotFound(DeviceError, InputError):
    """No such port: the path or URL the user gave does not exist."""

    exit_code = 2


class DeviceGone(DeviceError):
    """The device vanished while streaming (cable unplugged, power lost)."""


class RecordingError(TankdaqError):
    """A recording cannot be written or read (disk full, not an MCAP file)."""


class IdentificationError(TankdaqError):
    """A fit cannot be made from the data given (too short, no decay, NaN)."""


class BadRecordingInput(RecordingError, InputError):
    """A file given on the command line is not a readable tankdaq recording."""

    exit_code = 2


class BadIdentificationInput(IdentificationError, InputError):
    """The data handed to an estimator cannot be fitted (empty, NaN, no motion)."""

    exit_code = 2


class NotFittedError(TankdaqError, AttributeError):
    """A result of an estimator was asked for before ``fit`` made it (an AttributeError too, as it is one)."""
