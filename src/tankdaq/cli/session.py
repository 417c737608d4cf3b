"""``tankdaq session``: a guided test session, the campaign plan driving the recording run by run."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import typer

from ..config import validation
from ..errors import InputError
from .app import app, build_kernels_shown, catalogue_option, checked, err_console, handles_errors, say
from .record import (
    DEFAULT_LIVE_MODEL,
    STOPPED_EXIT_CODE,
    EventsFormat,
    EventsOption,
    LiveModelOption,
    SimSeedOption,
    SimSpeedOption,
    ViewerBindOption,
    ViewerOption,
    ViewerPortOption,
    ViewerWebPortOption,
    hull_option,
)

STOPPED = "session stopped; nothing is lost: continue with --resume --out {out}"

HELP = """Run a test session from a campaign PLAN, condition by condition, with the operator.

PLAN is a name in configs/campaigns or a .toml file:

\b
  hulls = ["swath"]            # the hulls this matrix covers (--hull picks one)
  axis = "roll"
  drafts = ["T", "1.1T"]       # run in this order, all angles of a draft together
  angles_deg = [10.0, 15.0]
  repeats = 2                  # decays kept per condition (default 1)
  [acceptance]                 # optional tolerances of the checks (defaults shown)
  angle_tolerance_deg = 1.0    # release angle vs nominal
  level_tolerance_deg = 1.0    # still water before the tilt
  min_half_cycles = 5
  min_r2 = 0.98
  rate_limit_deg_s = 290.0     # gyro saturation
  repeat_tolerance = 0.2       # B_eq vs the earlier repeats (relative)
  period_tolerance = 0.03      # natural period vs the earlier repeats
  max_flagged_samples = 0      # clipped samples after the release (more: rejected)

Every key and range is checked as the plan is read (docs/session.md): a typo is named with the
nearest known key, a value out of range is one line with its range.

Each decay is checked as it settles; a failed check is flagged and the operator asked to repeat.
Between decays the model is watched: a drift, a bump or an off-level rest is said as it happens, and
a decay released from a drifted level or before a bump settled is flagged.
Keys: Enter = the default, a accept, r reject and repeat, s skip, n TEXT adds a note.
Everything goes to OUT/session.jsonl; --resume continues after Ctrl-C, SIGTERM (at a question too:
it is asked again) or a crash. When every condition is done, the campaign report of the accepted
decays is written to OUT/report.
"""


def _terminal_line(prompt: str) -> str:
    """One line typed at the terminal, read from its descriptor. The session asks on a thread of its own
    (its main thread feeds the stream), which a stop leaves waiting: Python's buffered stdin would hold a
    lock the interpreter's exit needs (a fatal error at exit), a read of the descriptor holds none."""
    err_console.print(prompt, end="", markup=False, highlight=False)
    typed = b""
    while not typed.endswith(b"\n"):
        chunk = os.read(sys.stdin.fileno(), 4096)
        if not chunk:  # Ctrl-D
            raise InputError("the terminal closed at a question; continue with --resume")
        typed += chunk
    return typed.decode(errors="replace").rstrip("\r\n")


@app.command("session", help=HELP)
@handles_errors
def session_command(
    plan: str = typer.Argument(..., help="Campaign plan: a name in configs/campaigns or a .toml file."),
    port: str = typer.Option(..., "--port", help="Device path, pyserial URL, or 'sim'."),
    hull: str = hull_option(),
    out: Path = typer.Option(
        Path("session"),
        "--out",
        callback=checked(validation.output_dir),
        help="Folder for the recordings, the session file and the report.",
    ),
    resume: bool = typer.Option(False, "--resume", help="Continue the session in --out where it stopped."),
    yes: bool = typer.Option(False, "--yes", help="Answer every question with its default (Enter)."),
    responses: Path = typer.Option(
        None, "--responses", help="Answers, one per line (empty = Enter), used before --yes or the terminal."
    ),
    rate: float = typer.Option(
        100.0,
        "--rate",
        callback=checked(validation.output_rate_hz),
        help=f"Output rate (Hz): {validation.OUTPUT_RATES_TEXT}.",
    ),
    viewer: ViewerOption = None,
    viewer_bind: ViewerBindOption = None,
    viewer_port: ViewerPortOption = 9876,
    viewer_web_port: ViewerWebPortOption = 9090,
    model: LiveModelOption = DEFAULT_LIVE_MODEL,
    operator: str = typer.Option("", "--operator", help="Who runs the session (stored in every file)."),
    sim_speed: SimSpeedOption = 1.0,
    sim_seed: SimSeedOption = None,
    sim_faults: str = typer.Option("2:wrong-angle,5:double-push", "--sim-faults", hidden=True),
    catalogue: Annotated[str | None, catalogue_option()] = None,
    events: EventsOption = None,
) -> None:
    from ..acquire.listeners import EventStream
    from ..catalogue.hooks import CatalogueWriter, session_listener
    from ..config.plans import load_campaign_plan
    from ..physics.scenario import parse_fault_script
    from ..session.operator import ScriptedOrTerminalOperator, read_responses
    from ..session.runner import GuidedSession, SessionSettings

    answers = read_responses(responses)
    settings = SessionSettings(
        plan=load_campaign_plan(plan),
        hull=hull,
        record={
            "port": port,
            "out_dir": out,
            "rate_hz": rate,
            "viewer": viewer,
            "viewer_bind": viewer_bind,
            "viewer_port": viewer_port,
            "viewer_web_port": viewer_web_port,
            "model": model,
            "operator": operator,
            "sim_speed": sim_speed,
            "sim_seed": sim_seed,
        },
        sim_faults=parse_fault_script(sim_faults) if port == "sim" else {},
    )
    with CatalogueWriter.from_option(catalogue, say) as writer:
        session = GuidedSession(
            settings,
            ScriptedOrTerminalOperator(answers, yes, say, _terminal_line),
            on_line=say,
            on_progress=lambda progress: (
                err_console.rule(progress.line(), style="dim")
                if err_console.is_terminal
                else say(f"-- {progress.line()}")
            ),
            resume=resume,
            on_verdict=session_listener(writer, out),
            listeners=[EventStream(sys.stdout)] if events is EventsFormat.jsonl else [],
        )
        build_kernels_shown()
        try:
            state = session.run()
        except KeyboardInterrupt:  # a Ctrl-C while the report is written (a question or a decay: stopped)
            say(STOPPED.format(out=out))
            raise
        finally:
            writer.add_session(out)  # the log's last word (a decay stopped, recovered or missing)
    if session.stopped is not None:  # stopped (Ctrl-C, SIGTERM) in a decay or at a question: files closed
        say(STOPPED.format(out=out))
        raise typer.Exit(STOPPED_EXIT_CODE)
    from ..records import Verdict

    kept = sum(1 for r in state.runs if r.verdict == Verdict.ACCEPTED)
    say(f"session done: {kept} decays accepted of {state.decays} recorded; log {out / 'session.jsonl'}")
