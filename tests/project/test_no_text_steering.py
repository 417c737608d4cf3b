"""Nothing steers by the recorder's printed lines (issue 22): the pipeline's listeners get typed events
(``tankdaq.acquire.events``), programs read ``--events jsonl``. This reads every source, test and bench file
for a string test on one of those lines (``line.startswith("run 1: released")``, ``"released at" in
line``) and fails on each one found; the scan is shown to catch planted examples of both forms."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: How the recorder's event lines begin or what they say (``Event.line()`` of ``acquire.events``).
_WORDS = (
    r"(?:run|decay) \d*:?(?: released| amplitude| timeout| note| unplug| error|[\"'])|released\b|held at|"
    r"put back|(?:warning|note): (?:run|decay)|viewer:|device:|device gone|device back|stopping"
)
#: A line tested by its beginning, one of those words looked for in a text, or waited for.
PATTERNS = (
    re.compile(rf"\.(?:start|end)swith\(\s*\(?\s*f?[\"'](?:{_WORDS})"),
    re.compile(rf"[\"'](?:{_WORDS})[^\"'\n]*[\"']\s+(?:not\s+)?in\s+(?!\()"),
    re.compile(rf"wait(?!\w*event)\w*\([^)]*[\"'](?:{_WORDS})"),  # a helper that waits for such a line
)


def text_steering(path: Path) -> list[str]:
    """``FILE:LINE: text`` of each string test on the recorder's lines in ``path``."""
    found = []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if any(pattern.search(line) for pattern in PATTERNS):
            found.append(f"{path.relative_to(path.parents[1])}:{number}: {line.strip()}")
    return found


def test_no_source_or_test_matches_the_recorders_printed_lines() -> None:
    files = [path for folder in ("src", "tests", "bench") for path in sorted((ROOT / folder).rglob("*.py"))]
    files.remove(Path(__file__))  # this file names the patterns
    assert len(files) > 100
    found = [hit for path in files for hit in text_steering(path)]
    assert not found, "string tests on the recorder's lines (wait on typed events instead):\n" + "\n".join(
        found
    )


def test_the_scan_catches_a_planted_string_test_and_passes_typed_events(tmp_path: Path) -> None:
    planted = tmp_path / "pkg" / "planted.py"
    planted.parent.mkdir()
    steering = [
        'if line.startswith("run 1: released") and not plugged.is_set():',
        "if line.startswith('stopping'):",
        'ONCE = line.startswith(("viewer: ", "device: "))',
        'if line.startswith("run 1:") and " -> " in line:',
        'if line.startswith("warning: run 1: sensor flagged samples"):',
        'if "released at" in proc.stderr.readline():',
        'assert "released" in out',
        'assert f"stopping ({signum.name}): closing files" in err',
        'seen = [line for line in lines if "device gone" not in line]',
        '_wait_for(lines, seen, "run 2: amplitude")',
        '_wait_for_line(proc, "stderr", "released at")',
    ]
    typed = [
        "if isinstance(event, Released) and event.run == 1:",
        'if event["event"] == "released":',
        'return f"{where}: released at {abs(self.angle_deg):.2f} deg"',
        'held = "held at" if moving else "waiting"',
        'assert f"run tankdaq device reset {path}" in lines[0]',
        'assert "warning: implausible damping" in text.stdout',
        'kinds = [e["kind"] for e in events if e["kind"] in ("release", "settled")]',
    ]
    planted.write_text("\n".join(steering + typed) + "\n")
    found = text_steering(planted)
    assert [hit.split(": ", 1)[1] for hit in found] == steering, found
