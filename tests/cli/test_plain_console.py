"""Any console: a stream whose encoding cannot show B̂44, °, ² or ≈ (a Windows console or file in cp1252,
ASCII) gets plain text for exactly those characters (``cli.plain_text``), never a UnicodeEncodeError.

Real ``tankdaq`` processes under ``PYTHONIOENCODING``, their bytes decoded with the encoding they were
given: exit 0, no traceback, the plain words where the characters would be.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.cli.plain_text import HANDLER, install, plain

EXE = str(Path(sys.executable).with_name("tankdaq"))
DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "kvlcc2-roll-decay"
ENCODINGS = ("cp1252", "ascii")


def tankdaq(encoding: str, *args: object, env: dict[str, str] | None = None) -> tuple[str, str]:
    """stdout and stderr of a tankdaq command run with ``encoding`` on its streams (exit 0 asserted)."""
    done = subprocess.run(
        [EXE, *map(str, args)],
        capture_output=True,
        timeout=300,
        env={**os.environ, **(env or {}), "PYTHONIOENCODING": encoding},
        check=False,
    )
    out, err = done.stdout.decode(encoding), done.stderr.decode(encoding)  # each byte is of the encoding
    assert done.returncode == 0, err
    assert "Traceback" not in err and "UnicodeEncodeError" not in err
    return out, err


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("swath")
    return write_simulated_campaign(folder, ["swath"], "roll", [1.0], [4.0, 6.0], "mcap")


def test_each_character_tankdaq_prints_has_a_plain_form() -> None:
    assert [plain(c) for c in "°²³—–≈±×·√ρωΔé"] == [
        *("deg", "2", "3", "-", "-", "~", "+/-", "x", "*", "sqrt", "rho", "omega", "Delta", "e"),
    ]
    assert plain("\u2603") == "?"  # a snowman has no plain form: one mark, never an error


def test_only_what_the_encoding_cannot_show_is_replaced() -> None:
    install()  # registers the handler (this process's own streams are pytest's, left alone)
    text = "B̂44 5° R² ≈ 0.3 — ok"
    assert text.encode("cp1252", HANDLER).decode("cp1252") == "B44_hat 5° R² ~ 0.3 — ok"
    assert text.encode("ascii", HANDLER).decode("ascii") == "B44_hat 5deg R2 ~ 0.3 - ok"
    assert "ω̂ B̂F".encode("ascii", HANDLER) == b"omega_hat B_hatF"


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.slow
def test_predict_prints_b44_hat_in_plain_text(encoding: str) -> None:
    out, _ = tankdaq(encoding, "predict", "--hull", "kvlcc2")
    assert "B44_hat" in out and "B̂" not in out and "B_hatW" in out
    assert ("N*m*s" in out) == (encoding == "ascii")  # cp1252 shows the middle dot itself


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.slow
def test_identify_with_a_hull_runs_on_its_catalogue_and_campaign(
    encoding: str, recordings: list[Path], tmp_path: Path
) -> None:
    catalogue = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    out, err = tankdaq(
        encoding,
        "identify",
        *recordings,
        "--model",
        "b1,b2,c1,c3",
        "--hull",
        "swath",
        "--catalogue",
        catalogue,
    )
    assert "B44_hat" in out and "B̂" not in out + err
    out, _ = tankdaq(encoding, "runs", "--catalogue", catalogue)
    assert "B44_hat" in out and ("5deg" in out) == (encoding == "ascii")
    assert "swath" in out
    out, _ = tankdaq(encoding, "campaign", *recordings, "--model", "b1,b2,c1,c3", "--catalogue", "none")
    assert "| B44_hat |" in out and ("R2 angle" in out) == ("+/-" in out) == (encoding == "ascii")


@pytest.mark.skipif(not (DATA / "model_test_21338.csv").is_file(), reason=f"the KVLCC2 data is not at {DATA}")
@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.slow
def test_identify_a_real_decay_with_its_hull(encoding: str, tmp_path: Path) -> None:
    args = ["identify", DATA / "model_test_21338.csv", "--angle-unit", "rad", "--time-col", "time"]
    out, _ = tankdaq(encoding, *args, "--angle-col", "phi", "--hull", "kvlcc2", "--catalogue", "none")
    assert "B44_hat" in out and "B̂" not in out


@pytest.mark.slow
def test_the_c_locale_with_stdout_to_a_file(tmp_path: Path) -> None:
    """``LC_ALL=C`` and stdout redirected to a file: Python writes UTF-8 there (PEP 538/540), which shows
    everything; whatever the locale makes of it, the command finishes and the file reads back."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONIOENCODING", "PYTHONUTF8")}
    with (tmp_path / "out.txt").open("wb") as out:
        done = subprocess.run(
            [EXE, "predict", "--hull", "kvlcc2"],
            stdout=out,
            stderr=subprocess.PIPE,
            env={**env, "LC_ALL": "C"},
            timeout=300,
            check=False,
        )
    assert done.returncode == 0 and b"Traceback" not in done.stderr, done.stderr
    text = (tmp_path / "out.txt").read_bytes().decode("utf-8")  # ASCII's plain text is UTF-8 too
    assert "B̂44" in text or "B44_hat" in text


@pytest.mark.slow
def test_a_utf8_stream_is_left_as_it_is(recordings: list[Path]) -> None:
    out, _ = tankdaq("utf-8", "predict", "--hull", "kvlcc2")
    assert "B̂44" in out and "N·m·s" in out
