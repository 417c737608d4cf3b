"""``tankdaq --help`` and every ``COMMAND --help`` start without the heavy libraries (issue 14).

Not a timing: the help of every command is rendered in one fresh interpreter, and then the heavy
libraries must be absent from ``sys.modules`` (the commands that use them import them when they run).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("scipy", "numba", "matplotlib", "rerun", "distributed", "dask", "mcap")
#: Not heavy, but each was a tenth of a ``--help``: typer's pydantic coercion of an absent root
#: ``--help`` (cli.app.OneLineUsageErrors), rich before the first line printed (cli.app.err_console).
SLOW_TO_IMPORT = ("pydantic", "rich")

PROBE = """
import contextlib, io, json, sys
from typer.main import get_command
from tankdaq.cli import app

root = get_command(app)
paths = []
def walk(command, prefix):
    paths.append(prefix)
    for name, sub in sorted(getattr(command, "commands", {}).items()):
        walk(sub, [*prefix, name])
walk(root, [])
for path in paths:
    with contextlib.redirect_stdout(io.StringIO()) as shown:
        try:
            root.main([*path, "--help"], prog_name="tankdaq", standalone_mode=False)
        except SystemExit:
            pass
    assert "Usage" in shown.getvalue(), path
loaded = sorted({name.split(".")[0] for name in sys.modules} & set(json.loads(sys.argv[1])))
print(json.dumps({"commands": [" ".join(p) for p in paths], "loaded": loaded}))
"""


@pytest.mark.slow
def test_help_of_every_command_imports_no_heavy_library() -> None:
    done = subprocess.run(
        [sys.executable, "-c", PROBE, json.dumps(HEAVY + SLOW_TO_IMPORT)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert {"", "record", "replay", "campaign", "auv", "auv identify", "decode"} <= set(found["commands"])
    assert found["loaded"] == [], f"--help imported {found['loaded']}"


def test_every_command_is_registered_by_the_module_named_for_it() -> None:
    """``COMMAND_MODULES`` is what ``main`` imports for ``tankdaq COMMAND``: it must name the right module."""
    from tankdaq.cli import COMMAND_MODULES, app

    found = {info.name: info.callback.__module__ for info in app.registered_commands if info.callback}
    for group in app.registered_groups:
        (module,) = {
            info.callback.__module__ for info in group.typer_instance.registered_commands if info.callback
        }
        found[group.name] = module
    assert {name: module.rsplit(".", 1)[1] for name, module in found.items()} == COMMAND_MODULES


@pytest.mark.slow
def test_a_command_imports_only_its_own_module() -> None:
    """``tankdaq replay --help`` through the console entry point: the record room only, and its help."""
    probe = (
        "import sys\nsys.argv = ['tankdaq', 'replay', '--help']\nfrom tankdaq.cli import main\n"
        "try:\n    main()\nexcept SystemExit as exc:\n    assert exc.code in (0, None), exc.code\n"
        "print(sorted(m for m in sys.modules if m.startswith('tankdaq.cli.')))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "Usage: tankdaq replay" in done.stdout
    shared = "'tankdaq.cli.app', 'tankdaq.cli.plain_text'"  # the helpers and any console's output
    assert done.stdout.strip().splitlines()[-1] == f"[{shared}, 'tankdaq.cli.record']"
