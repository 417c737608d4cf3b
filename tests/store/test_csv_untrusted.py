"""Files a lab's tools write (issue 19): any CSV dialect, units decided from the data, every decay in a
file found, and bad files (malformed metadata, MCAP cut to a few bytes, another tool's MCAP) answered in
one line with exit code 2, a campaign going on past them with exit code 1. Real files, the real CLI."""

from __future__ import annotations

import json
import math
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from support.held_tilt import RATE_HZ, TRUTH, held_tilt
from support.ident_helpers import KVLCC2_21338
from tankdaq.cli import app
from tankdaq.physics.decay import simulate_decay

runner = CliRunner()


def hand_stopped(angles_deg, free_s: float = 5.0, noise_deg: float = 0.01, seed: int = 0):
    """Decays each tilted by hand (1 s), held 2 s, released, stopped by hand after ``free_s`` (0.3 s to
    rest) and left at rest 3 s; returns time (s) and angle (deg) with white noise."""
    parts = []
    for a0 in map(math.radians, angles_deg):
        free, _ = simulate_decay(TRUTH, np.arange(int(free_s * RATE_HZ)) / RATE_HZ, a0)
        parts += [
            np.linspace(0.0, a0, int(RATE_HZ), endpoint=False),
            np.full(int(2 * RATE_HZ), a0),
            free,
            free[-1] * np.linspace(1.0, 0.0, int(0.3 * RATE_HZ)),
            np.zeros(int(3 * RATE_HZ)),
        ]
    angle = np.degrees(np.concatenate(parts))
    angle += np.random.default_rng(seed).normal(0.0, noise_deg, angle.size)
    return np.arange(angle.size) / RATE_HZ, angle


def write_csv(path: Path, columns: dict[str, np.ndarray], sep: str = ",", comma: bool = False, **kw) -> Path:
    """Columns as text the way a spreadsheet writes them (``comma``: decimal commas; ``bom``, ``crlf``,
    ``trailing``: a separator ending every line, as Excel writes it, ``encoding``)."""
    end = (sep if kw.get("trailing") else "") + ("\r\n" if kw.get("crlf") else "\n")

    def cell(value: object) -> str:
        text = value if isinstance(value, str) else f"{value:.9g}"
        return text.replace(".", ",") if comma and not isinstance(value, str) else text

    n = len(next(iter(columns.values())))
    lines = [sep.join(columns)] + [sep.join(cell(col[i]) for col in columns.values()) for i in range(n)]
    text = ("\ufeff" if kw.get("bom") else "") + end.join(lines) + end
    path.write_bytes(text.encode(kw.get("encoding", "utf-8")))
    return path


def identify(*args: object):
    return runner.invoke(app, ["identify", *map(str, args)])


def one_error_line(result) -> str:
    """The one line a refused input gives (exit code checked by the caller), never a traceback."""
    assert "Traceback" not in result.output and isinstance(result.exception, SystemExit), result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def coefficients(result) -> dict[str, float]:
    assert result.exit_code == 0, result.output
    return {k: v["value"] for k, v in json.loads(result.stdout)["coefficients"].items()}


# ---------------------------------------------------------------------------------------------------
# Units from the data
# ---------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_kvlcc2_in_radians_is_read_as_radians_without_being_told():
    if not KVLCC2_21338.exists():
        pytest.skip(f"the KVLCC2 roll decay is not at {KVLCC2_21338} (shared data folder absent)")
    common = (KVLCC2_21338, "--time-col", "time", "--angle-col", "phi", "--model", "b1,c1", "--end", "20")
    found = identify(*common, "--json")
    told = identify(*common, "--angle-unit", "rad", "--json")
    assert coefficients(found) == coefficients(told)
    assert 0.03 < coefficients(found)["b1"] < 0.3 and 3 < coefficients(found)["c1"] < 10  # T0 2.5 s
    said = [line for line in found.stderr.splitlines() if "angle unit: rad" in line]
    assert len(said) == 1 and "10.4 deg read as radians" in said[0], found.stderr
    assert "angle unit" not in told.stderr


def test_time_in_milliseconds_is_read_as_milliseconds(tmp_path):
    t, angle, _ = held_tilt()
    path = write_csv(tmp_path / "ms.csv", {"t": t * 1000, "angle_deg": np.degrees(angle)})
    result = identify(path, "--time-col", "t", "--model", "ittc-quadratic", "--json")
    for term, value in coefficients(result).items():
        assert value == pytest.approx(TRUTH[term], rel=1e-3), term  # exact data: only the cut differs
    said = [line for line in result.stderr.splitlines() if "time unit: ms" in line]
    assert len(said) == 1 and "a model decay's period is 0.3-60 s" in said[0], result.stderr


@pytest.mark.slow
def test_an_xsens_sample_time_column_is_read_in_its_ticks(tmp_path):
    """MT Manager exports the device's time as SampleTimeFine, 10 kHz ticks from a day's start. Read as
    milliseconds (the only unit that made its 1.68 s period a decay's: 16.8 "s") c1 came out 100 times
    too small, with at most a time-step warning. The column's name says tick."""
    t, angle, _ = held_tilt()
    ticks = np.round(4_562_336 + t * 10_000)
    path = write_csv(tmp_path / "mtm.csv", {"SampleTimeFine": ticks, "Roll": np.degrees(angle)})
    result = identify(
        path, "--time-col", "SampleTimeFine", "--angle-col", "Roll", "--model", "ittc-quadratic", "--json"
    )
    for term, value in coefficients(result).items():
        assert value == pytest.approx(TRUTH[term], rel=1e-3), term
    assert "time unit: tick, 0.1 ms ('SampleTimeFine' is an Xsens SampleTimeFine)" in result.stderr
    other = write_csv(tmp_path / "t.csv", {"t": ticks, "angle_deg": np.degrees(angle)})
    told = identify(other, "--time-col", "t", "--time-unit", "tick", "--model", "ittc-quadratic", "--json")
    assert coefficients(told) == coefficients(result)
    unnamed = identify(other, "--time-col", "t", "--model", "ittc-quadratic", "--json")  # data cannot tell
    assert (
        "time unit: ms" in unnamed.stderr and "ticks the period is 1.7 s: --time-unit tick" in unnamed.stderr
    )


@pytest.mark.parametrize(
    ("columns", "args", "says"),
    [
        ({"time_s": 1.0, "angle_deg": 180 / math.pi}, ("--angle-unit", "rad"), "use --angle-unit deg"),
        ({"time_s": 1.0, "phi": 1.0}, ("--angle-col", "phi", "--angle-unit", "deg"), "use --angle-unit rad"),
        (
            {"t": 1000.0, "angle_deg": 180 / math.pi},
            ("--time-col", "t", "--time-unit", "s"),
            "--time-unit ms",
        ),
        ({"time_s": 1.0, "angle_deg": 180 / math.pi}, ("--time-unit", "ms"), "use --time-unit s"),
        ({"time_s": 1.0, "angle_deg": 1e3 * 180 / math.pi}, (), "no decay angle"),
        ({"time_s": 1.0, "angle_deg": 1e30}, (), "no decay angle"),
        ({"time_s": 1.0, "angle_deg": 180 / math.pi}, ("--angle-unit", "grad"), "use deg or rad"),
        ({"time_s": 1.0, "angle_deg": 180 / math.pi}, ("--time-unit", "min"), "use s, ms or tick (0.1 ms)"),
    ],
)
@pytest.mark.slow
def test_a_unit_that_makes_no_decay_is_refused_in_one_line(tmp_path, columns, args, says):
    """The user's unit gives 573 deg, 0.14 deg or a 1680 s period, or no unit gives a decay (scaled
    by 1e3..1e30): one line saying what the data look like and what to give, exit 2."""
    t, angle, _ = held_tilt()
    data = {name: (t if name in ("time_s", "t") else angle) * scale for name, scale in columns.items()}
    result = identify(write_csv(tmp_path / "d.csv", data), *args, "--model", "b1,c1")
    assert result.exit_code == 2
    assert says in one_error_line(result)


@pytest.mark.parametrize(
    ("written", "said"),
    [({"bom": True}, "UTF-8 byte-order mark"), ({"encoding": "cp1252"}, "Windows-1252 text")],
)
@pytest.mark.slow
def test_a_european_excel_file_is_read_and_its_dialect_said(tmp_path, written, said):
    t, angle, _ = held_tilt()
    columns = {"Zeit_s": t, "Winkel [°]": np.degrees(angle), "Kommentar": np.array(["gut"] * t.size)}
    path = write_csv(tmp_path / "excel.csv", columns, sep=";", comma=True, crlf=True, **written)
    result = identify(
        path, "--time-col", "Zeit_s", "--angle-col", "Winkel [°]", "--model", "ittc-quadratic", "--json"
    )
    for term, value in coefficients(result).items():
        assert value == pytest.approx(TRUTH[term], rel=1e-3), term
    lines = result.stderr.splitlines()
    assert f"excel.csv: read as semicolon-separated, decimal commas, {said}, CRLF line ends" in lines
    assert "excel.csv: text columns not read: Kommentar" in lines


# ---------------------------------------------------------------------------------------------------
# Every decay in a file
# ---------------------------------------------------------------------------------------------------


def test_three_hand_stopped_decays_are_three_runs(tmp_path):
    t, angle = hand_stopped([8.0, 6.0, 4.0])
    path = write_csv(tmp_path / "three.csv", {"time_s": t, "angle_deg": angle})
    result = identify(path, "--model", "ittc-quadratic", "--json")
    runs = json.loads(result.stdout)["runs"]
    assert [round(run["initial_angle_deg"]) for run in runs] == [8, 6, 4]
    for term, value in coefficients(result).items():  # 0.01 deg noise on 3 x 5 s: within 2 %
        assert value == pytest.approx(TRUTH[term], rel=0.02), term
    assert "three: 3 decays found, released at 3.0, 14.3, 25.6 s" in result.stderr


@pytest.mark.slow
def test_a_long_record_gives_every_decay(tmp_path):
    """55 hand-stopped decays in 2 10^5 rows (an afternoon's record): every one is a run."""
    period = 2 * math.pi / math.sqrt(TRUTH["c1"])
    tf = np.arange(int(30 * RATE_HZ)) / RATE_HZ
    shape = np.exp(-0.1 * tf) * np.cos(2 * math.pi * tf / period)
    rng = np.random.default_rng(3)
    angles = rng.uniform(3.0, 10.0, 55)
    one = [np.linspace(0, 1, 100, endpoint=False), np.ones(200), shape, shape[-1] * np.linspace(1, 0, 30)]
    angle = np.concatenate([np.concatenate([*(a * p for p in one), np.zeros(300)]) for a in angles])
    angle += rng.normal(0, 0.01, angle.size)
    path = write_csv(tmp_path / "long.csv", {"time_s": np.arange(angle.size) / RATE_HZ, "angle_deg": angle})
    from tankdaq.ident.inputs import input_notices, read_decays

    runs = read_decays(path)
    assert len(runs) == 55
    assert [math.degrees(run.angle[0]) for run in runs] == pytest.approx(angles, abs=0.05)
    assert input_notices(runs)[0].startswith("long: 55 decays found")


def test_a_part_without_a_decay_is_named(tmp_path):
    """Between two decays the model is tilted by hand and put back without a release: that part is not
    used, and one line says where and why."""
    t, angle = hand_stopped([8.0, 6.0])
    rock = np.concatenate([np.linspace(0, 5, 100), np.full(200, 5.0), np.linspace(5, 0, 100)])
    middle = int(t.size / 2)
    angle = np.concatenate([angle[:middle], rock, np.zeros(300), angle[middle:]])
    path = write_csv(tmp_path / "rocked.csv", {"time_s": np.arange(angle.size) / RATE_HZ, "angle_deg": angle})
    result = identify(path, "--model", "ittc-quadratic", "--json")
    assert [round(run["initial_angle_deg"]) for run in json.loads(result.stdout)["runs"]] == [8, 6]
    (line,) = [line for line in result.stderr.splitlines() if "not used" in line]
    assert line.startswith("rocked: ") and "no decay found" in line


# ---------------------------------------------------------------------------------------------------
# Bad files: one line, exit 2
# ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("value", ['["abc"]', "[null]", "[[1,2]]", '"soon"', "[3, 1]"])
@pytest.mark.slow
def test_malformed_release_metadata_is_one_line(tmp_path, value):
    t, angle, rate = held_tilt()
    path = tmp_path / "exported.csv"
    write_csv(path, {"time_s": t, "angle_rad": angle, "rate_rad_s": rate})
    path.write_text(f"# tankdaq export of x.mcap\n# release_t_s = {value}\n" + path.read_text())
    result = identify(path, "--model", "b1,c1")
    assert result.exit_code == 2
    assert "release_t_s" in one_error_line(result)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("--time-col", "time_s", "--angle-col", "time_s"), "both name 'time_s'"),
        (("--angle-col", "note"), "row 2, column 'note': 'ok' is not a number"),
        (("--rate-col", "time_s"), "is the time or angle column"),
    ],
)
def test_wrong_columns_are_one_line(tmp_path, args, says):
    t, angle, _ = held_tilt()
    notes = np.array(["ok"] * t.size)
    path = write_csv(tmp_path / "d.csv", {"time_s": t, "angle_deg": np.degrees(angle), "note": notes})
    result = identify(path, *args)
    assert result.exit_code == 2
    assert says in one_error_line(result)


def test_text_in_a_used_column_names_its_row_and_column(tmp_path):
    t, angle, _ = held_tilt()
    values = np.degrees(angle).astype(object)
    values[700] = "n/a"
    path = write_csv(tmp_path / "d.csv", {"time_s": t, "angle_deg": values})
    result = identify(path)
    assert result.exit_code == 2
    assert "row 702, column 'angle_deg': 'n/a' is not a number" in one_error_line(result)


@pytest.mark.parametrize("separator", [",", ";"])
def test_a_cell_longer_than_the_csv_module_takes_is_one_line(tmp_path, separator):
    """A 200 kB cell (a pasted log in a note column, a line without line ends) is over the csv module's
    limit: one line naming the row, not csv's own error."""
    t, angle, _ = held_tilt()
    notes = np.array(["ok"] * t.size, dtype=object)
    notes[5] = '"' + "z" * 200_000 + '"'
    columns = {"time_s": t, "angle_deg": np.degrees(angle), "note": notes}
    path = write_csv(tmp_path / "d.csv", columns, sep=separator, comma=separator == ";")
    result = identify(path)
    assert result.exit_code == 2
    assert "data line 6 (200" in one_error_line(result)


def test_a_file_given_twice_is_one_decay(tmp_path):
    """``identify a.csv a.csv`` (a shell glob that names a file twice): the file is read once, said so."""
    t, angle, _ = held_tilt()
    path = write_csv(tmp_path / "d.csv", {"time_s": t, "angle_deg": np.degrees(angle)})
    result = runner.invoke(app, ["identify", str(path), str(path), "--json", "--catalogue", "none"])
    assert result.exit_code == 0, result.output
    assert len(json.loads(result.stdout)["runs"]) == 1
    assert f"not read again: {path} is given twice" in result.stderr


def test_rows_out_of_time_order_are_named_as_such(tmp_path):
    """A sheet sorted by another column: the time goes back. Its "period" was read as -1.84 time units
    and the line asked for --time-unit; it names the samples that go back instead."""
    t, angle, _ = held_tilt()
    order = np.random.default_rng(1).permutation(t.size)
    path = write_csv(tmp_path / "d.csv", {"time_s": t[order], "angle_deg": np.degrees(angle)[order]})
    result = identify(path)
    assert result.exit_code == 2
    line = one_error_line(result)
    assert "column 'time_s' does not increase: sample " in line and "sort the rows by time" in line


def test_an_angle_column_of_nothing_but_nan_is_one_line_without_numpys_warnings(tmp_path):
    t, _, _ = held_tilt()
    path = write_csv(tmp_path / "d.csv", {"time_s": t, "angle_deg": np.full(t.size, np.nan)})
    with warnings.catch_warnings(record=True) as caught:  # a user's terminal shows what pytest would hide
        warnings.simplefilter("always")
        result = identify(path)
    assert not [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert result.exit_code == 2
    assert "the angle column holds NaN" in one_error_line(result)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, Path]:
    """A tankdaq recording, the same cut to 8, 20 and 36 bytes, and an MCAP written by another tool."""
    from mcap.writer import Writer

    from tankdaq.samples import SAMPLE_DTYPE
    from tankdaq.store.writer import RecordingWriter

    folder = tmp_path_factory.mktemp("recordings")
    t, angle, rate = held_tilt(6.0)
    samples = np.zeros(t.size, dtype=SAMPLE_DTYPE)
    samples["t"], samples["ticks"], samples["az"] = t, np.round(t * 1e4).astype(np.int64), 9.81
    samples["roll"], samples["p"] = angle, rate
    good = folder / "trimaran_T_roll_6deg.mcap"
    meta = {"axis": "roll", "hull": "trimaran", "draft": "T", "angle_nominal_deg": "6"}
    with RecordingWriter(good, meta, {}) as writer:
        writer.write_samples(samples)
        writer.write_event("release", "by hand", t_s=2.0)
    found = {"good": good}
    for size in (8, 20, 36):
        found[f"cut{size}"] = folder / f"cut{size}.mcap"
        found[f"cut{size}"].write_bytes(good.read_bytes()[:size])
    found["foreign"] = folder / "foreign.mcap"
    with found["foreign"].open("wb") as stream:  # another tool's /samples: not tankdaq's
        other = Writer(stream)
        other.start()
        channel = other.register_channel("/samples", "json", other.register_schema("x", "jsonschema", b"{}"))
        for i in range(50):
            other.add_message(channel, i, b'{"x": 1}', i)
        other.finish()
    return found


@pytest.mark.parametrize("command", ["identify", "export", "replay", "diagnose"])
@pytest.mark.parametrize("name", ["cut8", "cut20", "cut36", "foreign"])
@pytest.mark.slow
def test_a_short_or_foreign_mcap_is_one_line(recordings, tmp_path, command, name):
    extra = ["--out", str(tmp_path)] if command == "export" else []
    result = runner.invoke(app, [command, str(recordings[name]), *extra])
    assert result.exit_code == 2
    line = one_error_line(result)
    expected = "cut short at" if name.startswith("cut") else "not a tankdaq recording"
    assert expected in line and str(recordings[name]) in line
    assert not list(tmp_path.glob("*.csv"))  # export wrote nothing


def test_a_campaign_goes_on_past_bad_files(recordings, tmp_path):
    """A recording cut to 20 bytes, a dangling link and another tool's .mcap beside a good one: listed,
    the good one fitted and its table written, exit 1."""
    import shutil

    folder = tmp_path / "campaign"
    folder.mkdir()
    for name in ("good", "cut20", "foreign"):
        shutil.copy(recordings[name], folder)
    (folder / "dangling.mcap").symlink_to(tmp_path / "moved-away.mcap")
    result = runner.invoke(app, ["campaign", str(folder), "--jobs", "1", "--model", "b1,c1"])
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    skipped = [line for line in result.stderr.splitlines() if line.startswith("skipped: ")]
    assert len(skipped) == 3
    assert "cut20.mcap is an MCAP file cut short" in skipped[0]
    assert "dangling.mcap is a dangling link" in skipped[1] and "foreign.mcap" in skipped[2]
    assert "error: 3 of 4 files skipped" in result.stderr
    assert "| trimaran |" in result.stdout  # the good recording's group is in the table


@pytest.mark.parametrize("nominal", ["-6", "nan", "90"])
@pytest.mark.slow
def test_a_recording_whose_nominal_angle_is_no_release_angle_is_skipped(recordings, tmp_path, nominal):
    """An edited recording whose metadata gives the nominal angle -6 or nan grouped and reported as a
    "-6 deg" or "nan deg" condition (B_eq nan ± nan), with no word: it is skipped with its line."""
    from tankdaq.samples import SAMPLE_DTYPE
    from tankdaq.store.writer import RecordingWriter

    folder = tmp_path / "campaign"
    folder.mkdir()
    shutil.copy(recordings["good"], folder)
    t, angle, rate = held_tilt(6.0)
    samples = np.zeros(t.size, dtype=SAMPLE_DTYPE)
    samples["t"], samples["ticks"], samples["az"] = t, np.round(t * 1e4).astype(np.int64), 9.81
    samples["roll"], samples["p"] = angle, rate
    meta = {"axis": "roll", "hull": "trimaran", "draft": "T", "angle_nominal_deg": nominal}
    with RecordingWriter(folder / "edited.mcap", meta, {}) as writer:
        writer.write_samples(samples)
        writer.write_event("release", "by hand", t_s=2.0)
    result = runner.invoke(app, ["campaign", str(folder), "--jobs", "1", "--model", "b1,c1"])
    assert result.exit_code == 1, result.output
    (skipped,) = [line for line in result.stderr.splitlines() if line.startswith("skipped: ")]
    assert "edited.mcap: its metadata gives the nominal angle" in skipped and "not a release angle" in skipped
    groups = [line for line in result.stdout.splitlines() if line.startswith("| trimaran |")]
    assert len(groups) == 1 and "| 6 |" in groups[0]


# ---------------------------------------------------------------------------------------------------
# Any dialect of a known decay: the known coefficients
# ---------------------------------------------------------------------------------------------------


@st.composite
def dialects(draw):
    sep = draw(st.sampled_from([",", ";", "\t"]))
    return {
        "sep": sep,
        "comma": sep != "," and draw(st.booleans()),
        "bom": draw(st.booleans()),
        "crlf": draw(st.booleans()),
        "trailing": draw(st.booleans()),
        "text": draw(st.booleans()),
        "order": draw(st.permutations(["t", "angle", "rate", "note"])),
        "angle_unit": draw(st.sampled_from(["deg", "rad"])),
        "time_unit": draw(st.sampled_from(["s", "ms"])),
        "rate": draw(st.booleans()),
    }


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(dialect=dialects())
@pytest.mark.slow
def test_any_dialect_gives_the_known_coefficients(tmp_path, dialect):
    """Exact data written to 9 significant digits: the fit recovers the truth to about 1e-5, so 1e-3
    only allows for where the release cut falls. Every dialect drawn is read (none is refused)."""
    t, angle, rate = held_tilt()
    to_unit = 1.0 if dialect["angle_unit"] == "rad" else 180 / math.pi
    values = {
        "t": t * (1000.0 if dialect["time_unit"] == "ms" else 1.0),
        "angle": angle * to_unit,
        "rate": rate * to_unit,
        "note": np.array([f"run {i % 7}" for i in range(t.size)]),
    }
    keep = [
        c for c in dialect["order"] if (c != "note" or dialect["text"]) and (c != "rate" or dialect["rate"])
    ]
    path = write_csv(tmp_path / "dialect.csv", {f"my {c}": values[c] for c in keep}, **dialect)
    rate_col = ["--rate-col", "my rate"] if dialect["rate"] else []
    result = identify(
        path,
        "--time-col",
        "my t",
        "--angle-col",
        "my angle",
        *rate_col,
        "--model",
        "ittc-quadratic",
        "--json",
    )
    assert "Traceback" not in result.output
    for term, value in coefficients(result).items():  # every dialect drawn is one a spreadsheet writes
        assert value == pytest.approx(TRUTH[term], rel=1e-3), (term, dialect)
