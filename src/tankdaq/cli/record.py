"""``tankdaq record``, ``replay`` and ``demo``: the daemon in the tank lab and its replays."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from ..config import validation
from .app import (
    app,
    build_kernels_shown,
    catalogue_option,
    checked,
    draft_option,
    err_console,
    handles_errors,
    say,
)

if TYPE_CHECKING:  # the daemon imports numba, scipy and rerun: imported by the commands that run it
    from ..acquire.daemon import RecordSettings
    from ..acquire.events import DecayOutcome
    from ..acquire.sinks import Sink


class AxisChoice(StrEnum):
    roll = "roll"
    pitch = "pitch"
    auto = "auto"


def _viewer(value: str) -> str:
    from ..errors import InputError
    from ..viz.viewer import check_mode

    try:
        return check_mode(value)
    except InputError as exc:
        raise typer.BadParameter(str(exc)) from None


#: Options ``record`` and ``session`` share: the hull, the view, the live model, the hidden simulator pace.
def hull_option() -> Any:
    """The required ``--hull`` option of the commands that record (a typer default, hence ``Any``)."""
    return typer.Option(
        ...,
        "--hull",
        callback=checked(validation.known_hull, keep_input=True),
        help="The model tested: a hull name (tankdaq hulls) or a .toml file.",
    )


LiveModelOption = Annotated[
    str,
    typer.Option(
        "--model",
        callback=checked(validation.live_model, keep_input=True),
        help="Live model: auto (chosen by the data), terms (b1,b2,c1,c3) or alias.",
    ),
]
ViewerOption = Annotated[
    str | None,
    typer.Option(
        "--viewer",
        callback=lambda v: v if v is None else _viewer(v),
        help="spawn, save (an .rrd beside each MCAP), web (served here for a tablet or phone; web,save: "
        "and the .rrd), none, or a rerun URL.",
    ),
]
ViewerBindOption = Annotated[
    str | None,
    typer.Option(
        "--viewer-bind",
        help="Address the viewer listens on [default: web: this machine's network address; spawn: "
        "127.0.0.1]; 0.0.0.0 every network, only when asked.",
    ),
]
ViewerPortOption = Annotated[
    int,
    typer.Option(
        "--viewer-port", min=1, max=65535, help="Port of a spawned viewer, or of the web viewer's data."
    ),
]
ViewerWebPortOption = Annotated[
    int, typer.Option("--viewer-web-port", min=1, max=65535, help="Port of the web viewer's page (web).")
]
SimSpeedOption = Annotated[float, typer.Option("--sim-speed", min=0.1, max=50.0, hidden=True)]
SimSeedOption = Annotated[
    int | None,
    typer.Option(
        "--seed",
        "--sim-seed",
        min=0,
        help="Port sim: the simulator's seed (default: a new one each run, said in every file); the same "
        "seed plays the same test.",
    ),
]


class EventsFormat(StrEnum):
    jsonl = "jsonl"


EventsOption = Annotated[
    EventsFormat | None,
    typer.Option(
        "--events",
        help="Also write every event (held, released, settled, warnings, device, stop) to stdout, one "
        "JSON object per line, and nothing else: for programs (the lines on stderr are for people).",
    ),
]
DEFAULT_LIVE_MODEL = "auto"  # the refits move up physics.models.MODEL_FAMILY as the data allow


def event_listeners(events: EventsFormat | None) -> list[Sink]:
    """The pipeline's listeners a command adds: the printer of the event lines (stderr, each word
    explained once), and with ``--events jsonl`` each event as a JSON line on stdout."""
    import sys

    from ..acquire.listeners import EventPrinter, EventStream

    chosen: list[Sink] = [EventPrinter(say)]
    if events is EventsFormat.jsonl:
        chosen.append(EventStream(sys.stdout))
    return chosen


class _StatusLine:
    """One status line on stderr, refreshed in place on a terminal; event lines above it."""

    def __init__(self, runs: int | None) -> None:
        from rich.live import Live
        from rich.text import Text

        self.runs = runs
        self._text = Text("state: starting")
        self._live = Live(self._text, console=err_console, refresh_per_second=4, transient=True)

    def __enter__(self) -> _StatusLine:
        if err_console.is_terminal:
            self._live.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if err_console.is_terminal:
            self._live.__exit__(None, None, None)

    def status(self, status: object) -> None:
        self._text.plain = status.line(self.runs)  # type: ignore[attr-defined]


#: The exit code of a recording stopped by Ctrl-C, SIGTERM or SIGHUP (its files closed complete).
STOPPED_EXIT_CODE = 130


def run_record(
    settings: RecordSettings, catalogue: str | None = None, events: EventsFormat | None = None
) -> list[DecayOutcome]:
    """Run the daemon with a status line, print how many decay files it wrote (the files that exist);
    each file, once closed, goes into the run catalogue (``--catalogue``; a failure there is one line).

    Stopped by a signal, it exits 130 after the summary (typer.Exit), as Ctrl-C does anywhere.
    """
    from ..acquire.daemon import RecordDaemon
    from ..catalogue.hooks import CatalogueWriter
    from ..catalogue.sink import CatalogueSink

    build_kernels_shown()
    with CatalogueWriter.from_option(catalogue, say) as writer, _StatusLine(settings.runs) as line:
        daemon = RecordDaemon(
            settings, on_status=line.status, sinks=[CatalogueSink(writer), *event_listeners(events)]
        )
        outcomes = daemon.run()
    saved = daemon.recordings
    err_console.print(f"{len(saved)} decay(s) recorded under {settings.out_dir}", markup=False)
    if daemon.stopped_by is not None:
        raise typer.Exit(STOPPED_EXIT_CODE)
    return outcomes


@app.command("record")
@handles_errors
def record_command(
    port: str = typer.Option(
        ...,
        "--port",
        help="Device path, pyserial URL, 'auto' (the one Xsens device), 'sim' (built-in simulated MTi-G), "
        "or 'sim:FILE.mcap' (the device of a recording, played again).",
    ),
    draft: float = draft_option(...),
    angle: float = typer.Option(
        ..., "--angle", callback=checked(validation.release_angle_deg), help="Nominal release angle (deg)."
    ),
    hull: str = hull_option(),
    axis: AxisChoice = typer.Option(
        AxisChoice.roll, "--axis", case_sensitive=False, help="Decay axis, or auto."
    ),
    rate: float = typer.Option(
        100.0,
        "--rate",
        callback=checked(validation.output_rate_hz),
        help=f"Output rate (Hz): {validation.OUTPUT_RATES_TEXT}.",
    ),
    baud: int = typer.Option(
        None,
        "--baud",
        callback=checked(validation.baud_rate),
        help="Line rate to record at; tankdaq moves the device there (default: keep its rate if it "
        "carries --rate, else the slowest that does).",
    ),
    out: Path = typer.Option(
        Path("recordings"),
        "--out",
        callback=checked(validation.output_dir),
        help="Folder for the MCAP files (one per decay).",
    ),
    runs: int = typer.Option(
        None, "--runs", min=1, help="Stop after this many decays (default: until Ctrl-C)."
    ),
    viewer: ViewerOption = None,
    viewer_bind: ViewerBindOption = None,
    viewer_port: ViewerPortOption = 9876,
    viewer_web_port: ViewerWebPortOption = 9090,
    operator: str = typer.Option("", "--operator", help="Who ran the test (stored in the file)."),
    note: str = typer.Option("", "--note", help="A note stored in the file."),
    model: LiveModelOption = DEFAULT_LIVE_MODEL,
    sim_speed: SimSpeedOption = 1.0,
    sim_seed: SimSeedOption = None,
    catalogue: Annotated[str | None, catalogue_option()] = None,
    events: EventsOption = None,
) -> None:
    """Record decays: detect each release, write one MCAP per decay, fit and show it live.

    Each run's line says how it ended: settled (a whole decay, the swing below the settle threshold) or
    timed out, else partial (stopped by the operator, the device went away, closed after an error: the
    file is complete with what arrived, says so, and campaigns leave it out); a note line is worth
    knowing, a warning line means check that decay.
    """
    from ..acquire.daemon import RecordSettings

    settings = RecordSettings(
        port=port,
        draft=draft,
        angle_deg=angle,
        hull=hull,
        axis=axis.value,
        rate_hz=rate,
        baud=baud,
        out_dir=out,
        runs=runs,
        viewer=viewer,  # None: the default; the daemon prints the mode in use at start
        viewer_bind=viewer_bind,
        viewer_port=viewer_port,
        viewer_web_port=viewer_web_port,
        operator=operator,
        note=note,
        model=model,
        sim_speed=sim_speed,
        sim_seed=sim_seed,
    )
    run_record(settings, catalogue, events)


def _speed(value: str) -> float | None:
    if value == "max":
        return None
    try:
        speed = float(value)
    except ValueError:
        raise typer.BadParameter(f"{value!r}: give a factor like 1, 4 or 'max'") from None
    if not speed > 0:
        raise typer.BadParameter("speed must be positive, or 'max'")
    return speed


@app.command("replay")
@handles_errors
def replay_command(
    files: Annotated[
        list[Path], typer.Argument(callback=checked(validation.input_file), help="tankdaq MCAP recordings.")
    ],
    speed: str = typer.Option("1", "--speed", help="Playback speed factor, or 'max'."),
    viewer: str = typer.Option(
        None,
        "--viewer",
        callback=lambda v: v if v is None else _viewer(v),
        help="spawn, save (an .rrd beside each file), web (served here for a tablet or phone), none, "
        "or a rerun URL.",
    ),
    viewer_bind: ViewerBindOption = None,
    viewer_port: ViewerPortOption = 9876,
    viewer_web_port: ViewerWebPortOption = 9090,
    events: EventsOption = None,
) -> None:
    """Replay recordings: re-decode the raw bytes, re-detect the release, re-fit, show it again."""
    import contextlib

    from ..acquire.events import Event
    from ..acquire.live_panel import open_web_viewer
    from ..viz.web_viewer import is_web

    pace = _speed(speed)
    build_kernels_shown()
    listeners = event_listeners(events)
    with contextlib.ExitStack() as stack:
        web = None
        if is_web(viewer):  # one server for every file, before the first is read

            def said(event: Event) -> None:
                for listener in listeners:
                    listener.on_event(event)

            web = stack.enter_context(open_web_viewer(viewer_bind, viewer_port, viewer_web_port, said))
        _replay_files(files, pace, viewer, listeners, events, web)


def _replay_files(
    files: list[Path], pace: float | None, viewer: str | None, listeners: list[Sink], events: Any, web: Any
) -> None:
    """Each file replayed in turn, its decays said in one line each (with --events: as events)."""
    from ..acquire.events import said_instant
    from ..acquire.replay import replay_recording

    for path in files:
        outcomes = replay_recording(path, speed=pace, viewer=viewer, listeners=listeners, web=web)
        for o in outcomes if events is None else ():  # with --events the settled events say it
            fit = o.fit
            coeffs = "  ".join(f"{k}={v:.4g}" for k, v in fit.coefficients.items()) if fit else "no fit"
            when = said_instant(o.release_t, o.release_u95_s)
            typer.echo(f"{path.name}: release t={when} at {abs(o.angle_initial_deg):.2f} deg; {coeffs}")


def identify_recordings(
    paths: list[Path], report_dir: Path, model: str, truth: dict[str, float] | None = None
) -> None:
    """``tankdaq identify`` of the recordings (the same call, the same model for the same decays): its
    report, the fitted terms against the truth when known, and each decay's PNG."""
    from ..api.identification import identify
    from ..ident.report import predicted_angles
    from ..viz.plots import save_decay_fits
    from .app import TerminalProgress

    result = identify(paths, model, progress=TerminalProgress())
    typer.echo(result.text())
    for fit in result.fits:
        for line in _truth_lines(fit.estimator, truth or {}):
            typer.echo(line)
        for png in save_decay_fits(fit.runs, predicted_angles(fit.estimator, fit.runs), report_dir):
            typer.echo(f"plot: {png}")


def _truth_lines(estimator: Any, truth: dict[str, float]) -> list[str]:
    """Each fitted term against the simulator's truth, and the truth's terms the model leaves out."""
    from ..ident.comparison import truth_checks
    from ..physics.models import model_name

    checks = truth_checks(estimator, truth)
    lines = ["  identified vs the simulator's truth (hull config):"] if checks else []
    for check in checks:
        inside = "inside" if check.inside else "OUTSIDE"
        lines.append(f"    {check.term}: {check.value:.5g} vs {check.truth:.5g} ({inside} the 95 % interval)")
    left_out = [term for term, value in truth.items() if value and term not in estimator.terms_]
    if left_out:
        lines.append(
            f"  the truth also has {', '.join(left_out)}, which model {model_name(estimator.terms_)} leaves "
            f"out: its terms absorb them (--model {DEMO_TRUTH_MODEL} fits the truth's own terms)"
        )
    return lines


#: The demo's simulated hull rolls by seed 001 eq. (8), whose terms (b1 b2 b3 c1 c2 c3) ``--model
#: seed001-eq1`` fits; by default the demo chooses as ``identify`` does (the data choose).
DEMO_TRUTH_MODEL = "seed001-eq1"
DEMO_HULL = "swath"


@app.command("demo")
@handles_errors
def demo_command(
    out: Path = typer.Option(
        Path("recordings/demo"),
        "--out",
        callback=checked(validation.output_dir),
        help="Folder for the demo recordings.",
    ),
    runs: int = typer.Option(3, "--runs", min=1, help="How many decays to record."),
    sim_speed: float = typer.Option(4.0, "--sim-speed", min=0.1, max=50.0, help="Simulated clock speed-up."),
    model: LiveModelOption = DEFAULT_LIVE_MODEL,
    sim_seed: SimSeedOption = None,
) -> None:
    """The whole chain on the built-in simulated MTi-G: record decays, then identify them jointly
    (``tankdaq identify`` of the recordings: the model the data choose, or --model)."""
    from ..acquire.daemon import RecordSettings
    from ..config.hulls import load_hull

    err_console.print(
        f"recording {runs} simulated decays (hull {DEMO_HULL}, T, roll, 8 deg) into {out}; "
        f"live model {model}",
        markup=False,
    )
    settings = RecordSettings(
        port="sim",
        draft=1.0,
        angle_deg=8.0,
        hull=DEMO_HULL,
        out_dir=out,
        runs=runs,
        viewer="save",
        operator="demo",
        note="make demo",
        model=model,
        sim_speed=sim_speed,
        sim_seed=sim_seed,
    )
    outcomes = run_record(settings)
    paths = [o.path for o in outcomes if o.path is not None]
    truth = load_hull(DEMO_HULL).simulation_model("roll").coefficients(1.0)
    identify_recordings(paths, out, model, truth)
    from .way_in import demo_next_steps

    for line in demo_next_steps(out):
        typer.echo(line)
