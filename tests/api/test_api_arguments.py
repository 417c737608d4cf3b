"""The Python API checks its arguments where they enter (``api.arguments``): every public function,
constructor and method, called with each wrong kind of value for each of its arguments, either works or
raises one ``tankdaq.errors.InputError`` that names the argument, never a TypeError, AttributeError,
IndexError or KeyError from deep inside.

The cases are derived from the signatures (``inspect``), so an argument added later is tried too. A call
whose arguments are taken is stopped at the first task it starts (``StopAtWork``, a real ``Progress``):
the matrix reads tiny synthetic decays and fits nothing.
"""

from __future__ import annotations

import datetime
import inspect
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import tankdaq
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.catalogue.database import open_catalogue
from tankdaq.cli import app
from tankdaq.errors import InputError, TankdaqError

#: A wrong kind of value for any argument: what a notebook user types by mistake.
WRONG: dict[str, Any] = {
    "None": None,
    "int": 7,
    "negative": -1,
    "bool": True,
    "nan": math.nan,
    "inf": math.inf,
    "huge": 1e300,
    "huge int": 10**30,
    "str": "x",
    "empty str": "",
    "bytes": b"x",
    "list": [],
    "list of int": [3],
    "dict": {},
    "Path": Path("x"),
    "DataFrame": pd.DataFrame({"time_s": [0.0, 0.01], "angle_deg": [1.0, 0.9]}),
    "ndarray": np.zeros(3),
    "object": object(),
}

#: Every public callable with arguments: the API's functions, ``Reading``, the results' methods.
PUBLIC: dict[str, Callable[..., Any]] = {
    "read": tankdaq.read,
    "Reading": tankdaq.Reading,
    "identify": tankdaq.identify,
    "campaign": tankdaq.campaign,
    "compare_models": tankdaq.compare_models,
    "diagnose": tankdaq.diagnose,
    "simulate": tankdaq.simulate,
    "runs": tankdaq.runs,
    "set_reference": tankdaq.set_reference,
    "make_report": tankdaq.make_report,
    "import_archive": tankdaq.import_archive,
    "docs": tankdaq.docs,
    "Identification.plot": tankdaq.Identification.plot,
    "Recording.export": tankdaq.Recording.export,
    "Recording.to_csv": tankdaq.Recording.to_csv,
    "Recording.to_hdf5": tankdaq.Recording.to_hdf5,
    "Diagnosis.save_rrd": tankdaq.Diagnosis.save_rrd,
}


def _arguments(name: str) -> list[inspect.Parameter]:
    return [p for p in inspect.signature(PUBLIC[name]).parameters.values() if p.name != "self"]


CASES = [(name, parameter.name) for name in PUBLIC for parameter in _arguments(name)]


class Started(Exception):
    """The call took its arguments and began its work."""


class StopAtWork:
    """A ``Progress`` that ends the call at its first task: the arguments were all checked by then."""

    def line(self, text: str) -> None:
        pass

    def task(self, description: str, total: int | None = None) -> Any:
        raise Started(description)


@dataclass
class Made:
    """What the calls need: decay files, a recording, a fit, a diagnosis, an empty catalogue and one
    holding a fit (``fitted``: its fit 1 is a decay's, for ``set_reference``)."""

    folder: Path
    csv: Path
    recording: tankdaq.Recording
    run: Any
    result: tankdaq.Identification
    diagnosis: tankdaq.Diagnosis
    catalogue: str
    fitted: str


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Made:
    folder = tmp_path_factory.mktemp("decays")
    csvs = write_simulated_campaign(folder, ["swath"], "roll", [1.0], [5.0, 6.0], "csv")
    (mcap,) = write_simulated_campaign(
        tmp_path_factory.mktemp("rec"), ["swath"], "roll", [1.0], [5.0], "mcap"
    )
    run = tankdaq.read(csvs[0]).decays[0].run
    url = f"sqlite:///{tmp_path_factory.mktemp('catalogue') / 'catalogue.sqlite'}"
    with open_catalogue(url):
        pass  # an empty catalogue of tankdaq's
    result = tankdaq.identify(run, "b1,c1")
    diagnosis = tankdaq.diagnose(run, max_steps=0)
    fitted = f"sqlite:///{tmp_path_factory.mktemp('fitted') / 'catalogue.sqlite'}"
    done = CliRunner().invoke(app, ["identify", str(csvs[0]), "--model", "b1,c1", "--catalogue", fitted])
    assert done.exit_code == 0, done.output
    return Made(folder, csvs[0], tankdaq.read(mcap), run, result, diagnosis, url, fitted)


def _base(name: str, made: Made, here: Path) -> tuple[Callable[..., Any], dict[str, Any]]:
    """The callable (bound for a method) and valid values for its required arguments; a ``Reading`` is
    made and used (a CSV read with it), as its settings are."""
    stop = {"progress": StopAtWork()}
    if name.startswith("Recording."):
        copy = here / "own" / made.recording.path.name  # exports beside it land in a folder of this case
        copy.parent.mkdir()
        shutil.copy(made.recording.path, copy)
        recording = replace(made.recording, path=copy)
        out = {"out_dir": here / "out"}
        return getattr(recording, name.split(".")[1]), {"file_format": "csv", **out} if name.endswith(
            "export"
        ) else out
    calls: dict[str, tuple[Callable[..., Any], dict[str, Any]]] = {
        "read": (tankdaq.read, {"path": made.csv}),
        "Reading": (lambda **given: tankdaq.identify(made.csv, reading=tankdaq.Reading(**given), **stop), {}),
        "identify": (tankdaq.identify, {"sources": made.run, "model": "b1,c1", **stop}),
        "campaign": (tankdaq.campaign, {"inputs": made.folder, **stop}),
        "compare_models": (tankdaq.compare_models, {"sources": made.run, **stop}),
        "diagnose": (tankdaq.diagnose, {"sources": made.run, **stop}),
        "simulate": (tankdaq.simulate, {"out_dir": here / "sim", "decay_s": 2.0}),
        "runs": (tankdaq.runs, {"catalogue": made.catalogue}),
        "set_reference": (tankdaq.set_reference, {"fit_id": 1, "catalogue": made.fitted}),
        "make_report": (tankdaq.make_report, {"inputs": made.folder, **stop}),
        "import_archive": (
            tankdaq.import_archive,
            {"folder": made.folder, "out": here / "in", "catalogue": "none", **stop},
        ),
        "docs": (tankdaq.docs, {}),
        "Identification.plot": (made.result.plot, {}),
        "Diagnosis.save_rrd": (made.diagnosis.save_rrd, {"path": here / "story.rrd"}),
    }
    return calls[name]


def _names(message: str, argument: str, value: object) -> bool:
    """The line names the argument: as the API spells it, or as the command's option (the library's
    lines are the command line's: ``--time-col``, ``--end``); a path or name given is named itself."""
    option = "--" + argument.removesuffix("_s").replace("_", "-")
    given = isinstance(value, str | Path) and str(value) and str(value) in message
    return argument in message or argument.replace("_", "-") in message or option in message or bool(given)


@pytest.mark.parametrize(("name", "argument"), CASES, ids=[f"{n}-{a}" for n, a in CASES])
@pytest.mark.slow
def test_a_wrong_value_works_or_is_one_line_naming_its_argument(
    name: str, argument: str, made: Made, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    default = {p.name: p.default for p in _arguments(name)}[argument]
    failures = []
    for label, value in WRONG.items():
        if value is default or (isinstance(value, str) and value == default):
            continue  # the default is not a wrong value
        here = tmp_path / label.replace(" ", "_")
        here.mkdir()
        monkeypatch.chdir(here)  # a relative path given ("x") lands in this case's own folder
        call, base = _base(name, made, here)
        try:
            call(**{**base, argument: value})
        except Started:
            continue  # taken: the work began
        except TankdaqError as exc:
            line = str(exc)
            if not (isinstance(exc, InputError) and "\n" not in line and _names(line, argument, value)):
                failures.append(f"{label}: {type(exc).__name__}: {line}")
        except Exception as exc:  # the failure this test is for: a raw error from inside
            failures.append(f"{label}: {type(exc).__name__}: {exc}")
        finally:
            plt.close("all")
    assert not failures, f"{name}({argument}=...):\n" + "\n".join(failures)


def test_the_matrix_covers_every_public_name_that_takes_arguments() -> None:
    covered = {name.split(".")[0] for name in PUBLIC}
    takes = {
        name
        for name in tankdaq.__all__
        if callable(obj := getattr(tankdaq, name))
        and (not inspect.isclass(obj) or name == "Reading")
        and inspect.signature(obj).parameters
    }
    assert takes <= covered
    assert len(CASES) >= 80


# -- what the checks accept on purpose, and the refusals people meet first --------------------------


@pytest.mark.slow
def test_read_none_and_identify_none_name_the_argument(made: Made) -> None:
    with pytest.raises(InputError, match=r"^path: give a recording or decay file's path .*not None$"):
        tankdaq.read(None)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^sources: give a path, a Recording.*not None$"):
        tankdaq.identify(None)  # type: ignore[arg-type]


@pytest.mark.slow
def test_a_dataframe_of_a_decay_fits_as_its_file_does_and_read_refuses_one_by_name(made: Made) -> None:
    frame = pd.read_csv(made.csv)  # time_s, angle_deg, rate_deg_s: the documented columns
    by_file, by_frame = (tankdaq.identify(given, "b1,c1") for given in (made.csv, frame))
    assert by_frame.coefficients["value"].tolist() == by_file.coefficients["value"].tolist()
    with pytest.raises(Started):  # tankdaq.read's names (roll_deg) are taken too
        tankdaq.compare_models(frame.rename(columns={"angle_deg": "roll_deg"}), progress=StopAtWork())
    with pytest.raises(InputError, match=r"^sources DataFrame: give a DataFrame with columns time_s"):
        tankdaq.identify(frame.rename(columns={"time_s": "t"}))
    with pytest.raises(InputError, match=r"^path: .*not a DataFrame \(save a DataFrame with df.to_csv"):
        tankdaq.read(frame)  # type: ignore[arg-type]


@pytest.mark.slow
def test_plot_of_a_decay_that_is_not_there_says_how_many_there_are(made: Made) -> None:
    with pytest.raises(InputError, match=r"^decay: give a whole number from 0 to 0 \(this result has 1 "):
        made.result.plot(decay=99)
    with pytest.raises(InputError, match=r"^condition: "):
        made.result.plot(condition=1)
    assert made.result.plot(decay=-1) is not None  # the last, as a list counts


@pytest.mark.slow
def test_one_hull_given_as_a_string_is_one_hull(made: Made) -> None:
    with pytest.raises(Started):
        tankdaq.campaign(made.folder, hulls="swath", progress=StopAtWork())
    with pytest.raises(InputError, match="unknown hull 'nohull'"):  # the whole name, not 'n'
        tankdaq.campaign(made.folder, hulls="nohull", progress=StopAtWork())


@pytest.mark.slow
def test_a_path_a_year_and_a_date_are_taken_by_runs(made: Made) -> None:
    path = Path(made.catalogue.removeprefix("sqlite:///"))
    for since in (2026, datetime.date(2026, 1, 1), "2026-01-01"):
        assert len(tankdaq.runs(catalogue=path, since=since)) == 0  # the empty catalogue, read
    with pytest.raises(InputError, match=r"^since: give a date"):
        tankdaq.runs(catalogue=path, since=2026.5)  # type: ignore[arg-type]


def test_reading_normalises_what_it_takes_and_names_what_it_refuses() -> None:
    reading = tankdaq.Reading(start_s=np.float64(1.5), end_s=20, skip_half_cycles=np.int64(1))
    assert (reading.start_s, reading.end_s, reading.skip_half_cycles) == (1.5, 20.0, 1)
    assert type(reading.start_s) is float and type(reading.skip_half_cycles) is int
    with pytest.raises(
        InputError,
        match=r"^start_s: give a finite number of seconds from the release, at least 0, or None, not '5'$",
    ):
        tankdaq.Reading(start_s="5")  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^end_s: give a time after start_s \(5 s\), not 2 s$"):
        tankdaq.Reading(start_s=5, end_s=2)


@pytest.mark.slow
def test_a_refusal_comes_before_any_work(made: Made, tmp_path: Path) -> None:
    """A bad last argument is refused although the first ones would have started the work."""
    with pytest.raises(InputError, match=r"^progress: "):
        tankdaq.campaign(made.folder, report=tmp_path / "report", progress=7)  # type: ignore[arg-type]
    assert not (tmp_path / "report").exists()
    with pytest.raises(InputError, match=r"^decay_s: "):
        tankdaq.simulate(tmp_path / "sim", decay_s=math.nan)
    assert not (tmp_path / "sim").exists()
