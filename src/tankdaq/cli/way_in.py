"""What to type next: how to run ``tankdaq`` again from this shell, and the demo's next commands.

``make demo`` installs into ``.venv`` without activating it (make cannot change the user's shell), so
after it ``tankdaq`` alone is "command not found": the demo ends by saying the way in (activate, or
the script's own path) and the next commands on its files, written as they run from this folder.
"""

from __future__ import annotations

import os
import shlex
import shutil
import sys
from pathlib import Path


def way_in() -> tuple[str, str | None]:
    """The command that runs this tankdaq from this shell, and (None when ``tankdaq`` alone does) the
    line that says why it is a path and how to activate its environment instead."""
    scripts = Path(sys.executable).parent  # not resolved: a venv's python is a link out of the venv
    script = shutil.which("tankdaq", path=str(scripts))
    found = shutil.which("tankdaq")
    if script is None or (found is not None and os.path.samefile(found, script)):
        return "tankdaq", None
    shown = _from_here(scripts)
    command = shlex.quote(str(shown / Path(script).name))
    if (scripts / "activate").is_file():
        activate = shlex.quote(str(shown / "activate"))
        return command, (
            f"tankdaq is in {shown}, not on your PATH: activate it with `. {activate}` (then `tankdaq ...`), "
            f"or run {command}"
        )
    return command, f"tankdaq is in {shown}, not on your PATH: add that folder to PATH, or run {command}"


def demo_next_steps(out: Path) -> list[str]:
    """The lines the demo ends with: the way in, then commands on its recordings in ``out``."""
    command, how = way_in()
    files = f"{shlex.quote(str(out))}/*.mcap"  # the glob outside the quotes: the shell expands it
    return [
        *([how] if how else []),
        f"next, on the demo's recordings in {out}:",
        f"  {command} identify {files} --json",
        f"  {command} replay {files} --speed max",
    ]


def _from_here(folder: Path) -> Path:
    """``folder`` from the working folder when inside it (``.venv/bin``, as the user typed it), else whole."""
    try:
        return folder.relative_to(Path.cwd())
    except ValueError:
        return folder
