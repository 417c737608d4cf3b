"""The typer application and the small helpers every command shares.

Commands live in one module per room (``cli/decode.py``, ``cli/record.py``...)
and stay thin: parse arguments, call the library, print. Errors raised on
purpose (``TankdaqError``) become one line on stderr and the error's exit code.
"""

from __future__ import annotations

import contextlib
import functools
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any, TypeVar, cast

import typer
from typer import _click
from typer.core import TyperGroup, TyperOption
from typer.exceptions import TyperException

from ..errors import TankdaqError

if TYPE_CHECKING:  # rich is imported at the first line printed: it was a seventh of ``tankdaq --help``
    from rich.console import Console
    from rich.progress import Progress


class OneLineUsageErrors(TyperGroup):
    """The root command: a usage error (missing option, unknown option, bad value) is one line, exit 2.

    Click's form (usage, hint, blank line, error) is four lines; a person at the tank reads one.
    """

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, windows_expand_args, **extra)
        try:
            code = super().main(args, prog_name, complete_var, False, windows_expand_args, **extra)
        except TyperException as exc:  # click's usage errors and bad parameters
            message = exc.format_message()
            if "\n" in message:  # the help text, for a command given without arguments
                exc.show()  # type: ignore[attr-defined]
                sys.exit(exc.exit_code)
            ctx = getattr(exc, "ctx", None)
            hint = ""
            if ctx is not None and not isinstance(exc, UsageLine):  # ours already say what to do
                hint = f" ({ctx.command_path} --help lists the options)"
            err_console.print(
                f"error: {message.rstrip('.')}{hint}", markup=False, highlight=False, soft_wrap=True
            )
            sys.exit(exc.exit_code)
        except typer.Abort:
            err_console.print("aborted", markup=False)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)

    def get_help_option(self, ctx: _click.Context) -> TyperOption | None:
        return _absent_is_false(super().get_help_option(ctx))

    def get_command(self, ctx: _click.Context, cmd_name: str) -> _click.Command | None:
        command = super().get_command(ctx, cmd_name)
        if command is not None:  # a sub-group (auv, device, hulls) is parsed before its command's --help
            _absent_is_false(command.get_help_option(ctx))
        return command


def _absent_is_false(help_option: TyperOption | None) -> TyperOption | None:
    """``--help`` not given reads as False, not None: typer 0.29 passes a None through a pydantic
    TypeAdapter, and importing pydantic for that costs 0.1 s of every ``tankdaq COMMAND --help``."""
    if help_option is not None:
        help_option.default = False
    return help_option


app = typer.Typer(
    cls=OneLineUsageErrors,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help="tankdaq: record towing-tank decay tests from an Xsens MTi-G and identify damping and restoring."
    " A page cited as docs/TOPIC.md is printed by `tankdaq docs TOPIC` (`tankdaq docs` lists them).",
)


class _StderrConsole:
    """rich's Console on stderr, made when first used (a command's first line, never for --help)."""

    def __init__(self) -> None:
        self._console: Console | None = None

    def __getattr__(self, name: str) -> Any:
        if self._console is None:
            from rich.console import Console

            self._console = Console(stderr=True)
        return getattr(self._console, name)

    def __enter__(self) -> Console:  # rich's Live holds its console with ``with``
        return cast("Console", self.__getattr__("__enter__")())

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.__getattr__("__exit__")(exc_type, exc, tb)


#: Progress bars and status lines go to stderr so stdout stays machine-readable.
err_console = cast("Console", _StderrConsole())

F = TypeVar("F", bound=Callable[..., Any])


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print one error line and return the Exit to raise."""
    err_console.print(f"error: {message}", markup=False, highlight=False, soft_wrap=True)
    return typer.Exit(code)


def handles_errors(fn: F) -> F:
    """Turn TankdaqError into one line and its exit code; Ctrl-C into exit 130, quietly."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except TankdaqError as exc:
            raise fail(str(exc), exc.exit_code) from None
        except KeyboardInterrupt:
            err_console.print("interrupted", markup=False)
            raise typer.Exit(130) from None
        except BrokenPipeError:
            raise typer.Exit(0) from None

    return wrapper  # type: ignore[return-value]


class UsageLine(typer.BadParameter):
    """A bad parameter value whose message already names the option (no "Invalid value for" prefix)."""

    def format_message(self) -> str:
        return self.message


def checked(rule: Callable[..., Any], keep_input: bool = False, **settings: Any) -> Callable[[Any], Any]:
    """A typer callback/parser applying a ``tankdaq.config.validation`` rule; None (not given) passes.

    A list option is checked item by item; ``keep_input`` passes the value on as given (a model
    alias stays an alias) instead of the rule's normalised form. The rule's InputError becomes one
    line and exit 2 while the command line is parsed: before any device is opened or work starts.
    """

    def one(value: Any) -> Any:
        normalised = rule(value, **settings)
        return value if keep_input else normalised

    def apply(value: Any) -> Any:
        if value is None:
            return None
        try:
            if isinstance(value, list | tuple):
                return [one(item) for item in value]
            return one(value)
        except TankdaqError as exc:
            raise UsageLine(str(exc)) from None

    return apply


#: How every --draft shows in --help: the forms it takes (a factor of the design draft T).
DRAFT_METAVAR = "0.9T|T|1.1T"


def parse_draft_option(value: str) -> float:
    """typer parser for --draft: '0.9T', 'T', '1.1T' -> factor (bad values exit 2)."""
    from ..config.validation import draft_factor

    return checked(draft_factor)(value)


def draft_option(default: Any = "T", help: str = "Draft, a factor of the design draft T.") -> Any:
    """The --draft option of every command that takes one draft: parsed and shown in --help alike."""
    return typer.Option(default, "--draft", parser=parse_draft_option, metavar=DRAFT_METAVAR, help=help)


def say(line: str) -> None:
    """One line on stderr as written: no markup, no highlighting, never wrapped into two."""
    err_console.print(line, markup=False, highlight=False, soft_wrap=True)


def warn_truncated(runs: Iterable[Any]) -> list[str]:
    """One warning line per recording cut short among the decays read; the files, for ``--json``."""
    from ..api.identification import truncations

    notices = truncations(list(runs))
    for notice in notices.values():
        say(notice)
    return list(notices)


def say_cuts(lines: Iterable[str]) -> None:
    """Where each decay's free part was cut, and why (``ident.free_decay.cut_lines``): one line each."""
    for line in lines:
        say(f"cut: {line}")


def _print_version(value: bool) -> None:
    if value:
        from .._version import __version__

        typer.echo(f"tankdaq {__version__}")
        raise typer.Exit()


@app.callback()
def root(
    version: bool = typer.Option(
        False, "--version", callback=_print_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """tankdaq: record towing-tank decay tests from an Xsens MTi-G and identify damping and restoring."""


def progress_bar() -> Progress:
    """The progress display every long command uses: on stderr (stdout stays machine-readable), transient
    (an error after it stays the one line printed), counting done/total with the elapsed time."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
    )


def catalogue_option() -> Any:
    """``--catalogue`` of every command that writes or reads the run catalogue (docs/catalogue.md), for
    ``Annotated[str | None, catalogue_option()] = None``."""
    return typer.Option(
        "--catalogue",
        metavar="URL|PATH|none",
        help="Run catalogue: a SQLite file or folder, postgresql://..., or none "
        "[default: $TANKDAQ_CATALOGUE, else catalogue.sqlite in the user data folder].",
    )


def runs_option() -> Any:
    """``--runs QUERY`` of identify, campaign and diagnose: catalogued recordings in place of paths
    (``Annotated``, as ``catalogue_option``)."""
    return typer.Option(
        "--runs",
        metavar="QUERY",
        help='Catalogued recordings in place of paths, e.g. "hull=swath draft=1.1T since=2026-03".',
    )


def build_kernels_shown() -> None:
    """On a first run, build the native kernels under the line that says how long, how big and where,
    with a spinner and the elapsed time (not on a terminal: a line every few seconds and one at the end);
    the library then finds them built (or says why not itself)."""
    from ..ident import compiled
    from ..live.preparation import first_run_notice

    notice = first_run_notice()
    if notice is None:
        return
    say(notice)
    if not err_console.is_terminal:  # a pipe or a log: lines, since a spinner draws nothing there
        from ..heartbeat import heartbeat

        start = time.monotonic()
        with heartbeat("building native kernels", say):
            compiled.ensure_native()
        say(f"native kernels built ({time.monotonic() - start:.0f} s)")
        return
    with progress_bar() as progress:
        progress.add_task("building native kernels", total=None)
        compiled.ensure_native()


class TerminalProgress:
    """The API's ``Progress`` on the terminal: lines through ``say``, tasks as rows of one transient
    ``progress_bar`` (a task opened inside another joins its display: rich draws one live display).
    When stderr is not a terminal (a pipe, a log file), where a live bar draws nothing, tasks are plain
    lines instead, one at least every ``api.progress.EVERY_S`` of ``clock`` (``api.progress.Lines``)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._bar: Progress | None = None
        self._clock = clock

    def line(self, text: str) -> None:
        say(text)

    @contextlib.contextmanager
    def task(self, description: str, total: int | None = None) -> Iterator[Callable[..., None]]:
        if not err_console.is_terminal:
            from ..api.progress import Lines

            with Lines(say, clock=self._clock).task(description, total) as update:
                yield update
            return
        if self._bar is not None:
            yield self._updater(self._bar, self._bar.add_task(description, total=total))
            return
        with progress_bar() as bar:
            self._bar = bar
            try:
                yield self._updater(bar, bar.add_task(description, total=total))
            finally:
                self._bar = None

    @staticmethod
    def _updater(bar: Progress, task: Any) -> Callable[..., None]:
        def update(done: int, total: int | None = None, description: str | None = None) -> None:
            bar.update(task, completed=done, total=total, description=description)

        return update
