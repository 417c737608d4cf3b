"""Hull and plan files are untrusted input: every bad value is one line and exit 2 where the file is read,
before a device, a simulator or an output file opens, and nothing is ever created outside the output
folder (issue 19, "no confident wrong answer")."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from tankdaq.cli import app
from tankdaq.config.hulls import load_hull
from tankdaq.config.plans import load_campaign_plan
from tankdaq.errors import InputError

runner = CliRunner()

HULL = """name = "h"
description = "a test hull"
[dimensions]
displacement_kg = 20.0
[axes.roll]
gm_m = 0.05
radius_of_gyration_m = 0.12
[simulation.roll.drafts."T"]
b1 = 0.3
b2 = 0.02
c1 = 14.0
"""

PLAN = """hulls = ["h"]
axis = "roll"
drafts = ["T"]
angles_deg = [10.0]
"""


#: The line ``live.preparation.prepare_identifier`` prints where the native kernels cannot be had and numba's
#: JIT serves (a notice, not an error; it comes before the file reading that refuses).
KERNEL_NOTICE = "identifier kernels on numba's JIT"


def tree(root: Path) -> set[Path]:
    """Every path under ``root`` (what a refused command must leave unchanged)."""
    return set(root.rglob("*"))


@pytest.fixture
def lab(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working folder two levels below the test's tmp folder (so an escape two levels up is seen),
    with an empty user hull folder."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    monkeypatch.setenv("TANKDAQ_HULLS_DIR", str(tmp_path / "userhulls"))
    return work


def refused(args: list[str], root: Path, phrase: str, code: int = 2) -> str:
    """Run ``tankdaq ARGS``: the exit code, one line (no traceback) holding ``phrase``, nothing created."""
    before = tree(root)
    result = runner.invoke(app, args)
    lines = [
        line for line in result.output.splitlines() if line.strip() and not line.startswith(KERNEL_NOTICE)
    ]
    assert result.exit_code == code, result.output
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    assert phrase in lines[0], lines[0]
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit)
    assert tree(root) == before, tree(root) - before
    return lines[0]


def edited(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new)


HULL_CASES = {
    "negative GM": (edited(HULL, "gm_m = 0.05", "gm_m = -0.05"), "gm_m must be a number above 0"),
    "negative displacement": (
        edited(HULL, "displacement_kg = 20.0", "displacement_kg = -20.0"),
        "displacement_kg must be a number above 0",
    ),
    "zero beam": (  # B̂44 divides by the beam: ZeroDivisionError before
        edited(HULL, "displacement_kg = 20.0", "displacement_kg = 20.0\nbeam_m = 0"),
        "dimensions.beam_m must be a number above 0",
    ),
    "NaN GM": (edited(HULL, "gm_m = 0.05", "gm_m = nan"), "gm_m = nan is not finite"),
    "GM a string": (edited(HULL, "gm_m = 0.05", 'gm_m = "0.05"'), "gm_m must be a number"),
    "huge GM": (edited(HULL, "gm_m = 0.05", "gm_m = 1" + "0" * 400), "gm_m = 1000"),
    "huge displacement": (edited(HULL, "displacement_kg = 20.0", "displacement_kg = 1e300"), "too large"),
    "duplicate draft": (
        HULL + '[simulation.roll.drafts."1.0T"]\nb1 = 0.3\nc1 = 10.0\n',
        "drafts 'T' and '1.0T' are the same draft",
    ),
    "name with a slash": (edited(HULL, 'name = "h"', 'name = "a/b"'), "cannot be part of a file name"),
    "name up two folders": (edited(HULL, 'name = "h"', 'name = "../../x"'), "cannot be part of a file name"),
    "name 300 long": (edited(HULL, 'name = "h"', f'name = "{"x" * 300}"'), "at most 64 characters"),
    "name with NUL": (edited(HULL, 'name = "h"', 'name = "a\\u0000b"'), "cannot be part of a file name"),
    "absolute name": (edited(HULL, 'name = "h"', 'name = "/etc/x"'), "cannot be part of a file name"),
    "negative stiffness": (edited(HULL, "c1 = 14.0", "c1 = -14.0"), "is not positive (the model capsizes)"),
    "NaN stiffness": (edited(HULL, "c1 = 14.0", "c1 = nan"), "c1 = nan is not finite"),
    "stiffness too high": (edited(HULL, "c1 = 14.0", "c1 = 1e6"), "the natural period 0.00628 s is outside"),
    "negative damping": (
        edited(HULL, "b1 = 0.3", "b1 = -2.0"),
        "the simulator's coefficients must give a decay",
    ),
    "unknown term": (edited(HULL, "b2 = 0.02", "b9 = 0.02"), "unknown key 'b9'; known: b1, b2"),
    "nested 100 000 deep": ("a = " + "[" * 100_000 + "]" * 100_000 + "\n", "nested too deeply"),
    "not UTF-8": ('name = "\xff"\n', "not UTF-8"),
}


@pytest.mark.parametrize("case", HULL_CASES)
@pytest.mark.slow
def test_a_bad_hull_is_one_line_at_load(case: str, lab: Path, tmp_path: Path) -> None:
    text, phrase = HULL_CASES[case]
    hull = lab / "h.toml"
    hull.write_bytes(text.encode("latin-1") if case == "not UTF-8" else text.encode())
    refused(["hulls", "show", str(hull)], tmp_path, phrase)


def test_the_refused_hulls_were_accepted_before_and_the_good_one_still_is(lab: Path) -> None:
    """The base hull loads; its total inertia is positive (a negative GM gave -0.685 kg m^2 before)."""
    path = lab / "h.toml"
    path.write_text(HULL)
    hull = load_hull(str(path))
    assert hull.name == "h" and hull.particulars("roll").gm_m == 0.05
    assert hull.dry_inertia_kg_m2("roll") == pytest.approx(20.0 * 0.12**2)


@pytest.mark.parametrize(
    ("case", "text", "port"),
    [
        ("name two folders up", edited(HULL, 'name = "h"', 'name = "../../x"'), "sim"),
        ("absolute name", edited(HULL, 'name = "h"', 'name = "/tmp/x"'), "sim"),
        ("negative damping", edited(HULL, "b1 = 0.3", "b1 = -2.0"), "sim"),
    ],
)
def test_record_refuses_the_hull_before_anything_opens(
    case: str, text: str, port: str, lab: Path, tmp_path: Path
):
    (lab / "h.toml").write_text(text)
    args = ["record", "--port", port, "--hull", "h.toml", "--draft", "T", "--angle", "8", "--out", "out"]
    refused([*args, "--viewer", "none"], tmp_path, "h.toml")


def test_simulate_refuses_a_hull_that_does_not_decay(lab: Path, tmp_path: Path) -> None:
    (lab / "h.toml").write_text(edited(HULL, "b1 = 0.3", "b1 = -2.0"))
    line = refused(["simulate", "--hull", "h.toml", "--runs", "1"], tmp_path, "must give a decay")
    assert "not damped" in line


def test_the_simulator_refuses_a_period_its_rate_cannot_show(lab: Path, tmp_path: Path) -> None:
    """swath's roll period (1.66 s) is 1.7 samples at 1 Hz: refused before the simulator starts."""
    args = ["record", "--port", "sim", "--hull", "swath", "--draft", "T", "--angle", "8", "--rate", "1"]
    line = refused([*args, "--out", "out", "--viewer", "none"], tmp_path, "samples at 1 Hz")
    assert "give a faster rate" in line


PLAN_CASES = {
    "a typo": (PLAN + "repeat = 3\n", "unknown key 'repeat'; did you mean 'repeats'?"),
    "repeats 1.5": (PLAN + "repeats = 1.5\n", "repeats must be a whole number from 1 to 100, not 1.5"),
    "repeats 1e9": (PLAN + "repeats = 1000000000\n", "repeats must be a whole number from 1 to 100"),
    "repeats inf": (PLAN + "repeats = inf\n", "repeats = inf is not finite"),
    "repeats true": (PLAN + "repeats = true\n", "repeats must be a whole number"),
    "hulls a string": (edited(PLAN, 'hulls = ["h"]', 'hulls = "swath"'), "hulls must be a non-empty list"),
    "no angles": (
        edited(PLAN, "angles_deg = [10.0]", "angles_deg = []"),
        "angles_deg must be a non-empty list",
    ),
    "no drafts": (edited(PLAN, 'drafts = ["T"]', "drafts = []"), "drafts must be a non-empty list"),
    "same draft twice": (edited(PLAN, 'drafts = ["T"]', 'drafts = ["T", "1.0T"]'), "are the same draft"),
    "angle 90": (edited(PLAN, "angles_deg = [10.0]", "angles_deg = [90.0]"), "at most 45"),
    "axis auto": (
        edited(PLAN, 'axis = "roll"', 'axis = "auto"'),
        "axis must be one of roll, pitch, not 'auto'",
    ),
    "min_r2 2": (PLAN + "[acceptance]\nmin_r2 = 2.0\n", "min_r2 must be a number above 0 and at most 0.9999"),
    "acceptance typo": (PLAN + "[acceptance]\nmin_r = 0.9\n", "did you mean 'min_r2'?"),
    "angle huge": (edited(PLAN, "angles_deg = [10.0]", "angles_deg = [1" + "0" * 400 + "]"), "too large"),
}


@pytest.mark.parametrize("case", PLAN_CASES)
@pytest.mark.slow
def test_a_bad_plan_is_one_line_before_anything_is_written(case: str, lab: Path, tmp_path: Path) -> None:
    text, phrase = PLAN_CASES[case]
    (lab / "p.toml").write_text(text)
    refused(["simulate-campaign", "out", "--plan", "p.toml", "--hull", "swath"], tmp_path, phrase)
    args = [
        "session",
        "p.toml",
        "--port",
        "sim",
        "--hull",
        "swath",
        "--out",
        "s",
        "--yes",
        "--viewer",
        "none",
    ]
    refused(args, tmp_path, phrase)


def test_a_hull_folder_with_a_bad_file_lists_the_good_ones(lab: Path, tmp_path: Path) -> None:
    folder = tmp_path / "userhulls"
    folder.mkdir()
    (folder / "good.toml").write_text(edited(HULL, 'name = "h"', 'name = "good"'))
    (folder / "broken.toml").write_text("x = [\n")
    (folder / "negative.toml").write_text(edited(HULL, "gm_m = 0.05", "gm_m = -1.0"))
    result = runner.invoke(app, ["hulls"])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "good: a test hull" in result.stdout and "swath:" in result.stdout  # the good ones, listed
    skipped = [line for line in result.output.splitlines() if line.startswith("skipped: ")]
    assert len(skipped) == 2 and "broken.toml" in skipped[0] and "negative.toml" in skipped[1]
    assert "2 hull file(s) skipped" in result.output.splitlines()[-1]


def test_names_and_paths_stay_in_their_folder(tmp_path: Path) -> None:
    from tankdaq.config.rules import path_in, safe_name

    assert safe_name("kvlcc2_model-3", "hull") == "kvlcc2_model-3"
    for bad in ("a/b", "..", "../x", "x" * 65, "a\0b", "", "-x", "a b", "a.b", 7):
        with pytest.raises(InputError, match="cannot be part of a file name"):
            safe_name(bad, "hull")
    assert path_in(tmp_path, "a.png") == tmp_path / "a.png"
    for bad in ("../a.png", "x/../../a", "/abs", "..", "a\\b", "a\0"):
        with pytest.raises(InputError, match="would leave the folder"):
            path_in(tmp_path, bad)


def test_recording_names_refuse_an_unsafe_hull() -> None:
    from tankdaq.store.naming import recording_name

    assert recording_name("swath", 1.0, "roll", 8.0, 1).startswith("swath_T_roll_8deg_")
    with pytest.raises(InputError, match="cannot be part of a file name"):
        recording_name("../../x", 1.0, "roll", 8.0, 1)


@pytest.fixture
def one_csv(lab: Path) -> Path:
    from tankdaq.campaign.synthetic import write_simulated_campaign

    folder = lab / "rec"
    write_simulated_campaign(folder, ["swath"], "roll", [1.0], [8.0], "csv", seed=1)
    return folder


def test_a_sidecar_hull_that_leaves_the_folder_is_one_line(one_csv: Path, tmp_path: Path) -> None:
    (csv,) = one_csv.glob("*.csv")
    renamed = csv.rename(one_csv / "decay.csv")
    renamed.with_suffix(".json").write_text(
        json.dumps({"hull": "../../ESCAPED", "axis": "roll", "angle_deg": 8})
    )
    refused(["campaign", str(one_csv), "--report", "report"], tmp_path, "cannot be part of a file name")


def test_campaign_jobs_are_bounded_by_the_cores(one_csv: Path) -> None:
    result = runner.invoke(app, ["campaign", str(one_csv), "--jobs", "100000"])
    assert result.exit_code == 0, result.output
    cores = len(os.sched_getaffinity(0))
    assert (
        f"--jobs 100000: this machine gives tankdaq {cores} cores; running {cores} workers" in result.output
    )


def test_an_unreachable_dask_scheduler_is_one_line(one_csv: Path, tmp_path: Path) -> None:
    pytest.importorskip("distributed", reason="the dask extra is not installed (pip install 'tankdaq[dask]')")
    args = ["campaign", str(one_csv), "--executor", "dask", "--scheduler"]
    result = runner.invoke(app, [*args, "tcp://127.0.0.1:1"])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert len(errors) == 1 and "cannot reach the Dask scheduler at tcp://127.0.0.1:1 within 5 s" in errors[0]
    refused([*args, "no-scheme"], tmp_path, "--scheduler 'no-scheme' not understood")


# --------------------------------------------------------------------------------------------------
# Random files: load, or one line
# --------------------------------------------------------------------------------------------------

PLAN_KEYS = ["description", "hulls", "axis", "drafts", "angles_deg", "repeats", "repeat", "acceptance",
             "min_r2", "angle_tolerance_deg", "min_half_cycles", "period_tolerance", "angle"]  # fmt: skip

scalars = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**450), max_value=10**450),
    st.sampled_from(
        [0.05, 14.0, 0.3, 1.0, 10.0, 20.0, -2.0, 1e6, 1.5, 0, math.inf, math.nan, 10**400, 1e300]
    ),
    st.booleans(),
    st.text(max_size=12),
    st.sampled_from(["swath", "roll", "pitch", "auto", "T", "1.1T", "../x", "a/b", "x" * 70]),
)


def values(keys: list[str]) -> st.SearchStrategy[object]:
    """A scalar, or lists and tables of them (keys from ``keys``) nested a few deep."""
    return st.recursive(
        scalars,
        lambda inner: st.one_of(
            st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(keys), inner, max_size=5)
        ),
        max_leaves=12,
    )


def tables(keys: list[str], leaf: st.SearchStrategy[object]) -> st.SearchStrategy[object]:
    """Mostly a table of ``keys`` (known ones and typos) to ``leaf``; sometimes anything else."""
    return st.dictionaries(st.sampled_from(keys), leaf, max_size=5) | values(keys)


ANY = values(["x", "T", "b1"])
#: Where a number belongs: the edge cases first (non-finite, huge, negative, not a number at all).
EDGES = [math.inf, -math.inf, math.nan, 10**400, 1e300, -1.0, 0, 1.5, True, "0.1", [], {}]
NUMBER = st.one_of(st.sampled_from(EDGES), st.sampled_from(EDGES), st.floats(), ANY)
COEFFICIENTS = tables(["b1", "b2", "b3", "c1", "c3", "s1", "b9"], NUMBER)
HULLS = st.fixed_dictionaries(
    {},
    optional={
        "name": ANY,
        "description": ANY,
        "dimensions": tables(["displacement_kg", "length_m", "dispacement_kg"], NUMBER),
        "axes": tables(
            ["roll", "pitch", "yaw"], tables(["gm_m", "radius_of_gyration_m", "note", "gm"], NUMBER)
        ),
        "simulation": tables(
            ["roll", "pitch", "heave"],
            tables(["drafts", "source", "draft"], tables(["T", "1.0T", "1.1T", "0.1T", "x"], COEFFICIENTS)),
        ),
        "sources": ANY,
        "nme": ANY,
    },
)


def toml_value(value: object) -> str:
    """TOML for a generated value: inline tables and arrays, every float and integer as TOML writes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return (
            "nan"
            if math.isnan(value)
            else ("inf" if value > 0 else "-inf")
            if math.isinf(value)
            else repr(value)
        )
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(map(toml_value, value)) + "]"
    assert isinstance(value, dict)
    return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"


def toml_file(table: dict[str, object]) -> str:
    return "".join(f"{json.dumps(k)} = {toml_value(v)}\n" for k, v in table.items())


def loads_or_one_line(load, path: Path) -> None:  # type: ignore[no-untyped-def]
    try:
        load(str(path))
    except InputError as exc:
        assert "\n" not in str(exc) and str(exc)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(table=HULLS)
@pytest.mark.slow
def test_random_hull_files_load_or_give_one_line(table: dict[str, object], tmp_path: Path) -> None:
    path = tmp_path / "random.toml"
    path.write_text(toml_file(table))
    loads_or_one_line(load_hull, path)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    table=st.fixed_dictionaries(
        {"hulls": values(PLAN_KEYS), "axis": values(PLAN_KEYS), "drafts": values(PLAN_KEYS)},
        optional={
            **{k: values(PLAN_KEYS) for k in ("description", "repeat", "angle")},
            "repeats": NUMBER,
            "angles_deg": st.lists(NUMBER, max_size=3) | NUMBER,
            "acceptance": tables(["min_r2", "angle_tolerance_deg", "min_half_cycles", "min_r"], NUMBER),
        },
    )
)
@pytest.mark.slow
def test_random_plan_files_load_or_give_one_line(table: dict[str, object], tmp_path: Path) -> None:
    path = tmp_path / "random.toml"
    path.write_text(toml_file(table))
    loads_or_one_line(load_campaign_plan, path)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    coefficients=st.dictionaries(
        st.sampled_from(["b1", "b2", "b3", "c1", "c2", "c3", "s1"]),
        st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([0.3, 14.0, -2.0, 60.0]),
        max_size=5,
    )
)
def test_random_simulation_coefficients_load_or_give_one_line(coefficients: dict, tmp_path: Path) -> None:
    base = HULL[: HULL.index("[simulation")] + '[simulation.roll.drafts."T"]\n'
    path = tmp_path / "random.toml"
    path.write_text(base + "".join(f"{k} = {toml_value(v)}\n" for k, v in coefficients.items()))
    loads_or_one_line(load_hull, path)


HULL_VALUES = [
    "gm_m = 0.05",
    "radius_of_gyration_m = 0.12",
    "displacement_kg = 20.0",
    "b1 = 0.3",
    "c1 = 14.0",
]
PLAN_VALUES = ['hulls = ["h"]', 'axis = "roll"', 'drafts = ["T"]', "angles_deg = [10.0]"]


@pytest.mark.parametrize("edge", EDGES, ids=repr)
def test_every_value_of_a_hull_and_a_plan_takes_any_edge_value(edge: object, tmp_path: Path) -> None:
    """Each value of the hull and the plan replaced in turn by each edge value (a float too large, an
    integer of 400 digits, nan, a string, a list, a table...): loads, or one line."""
    path = tmp_path / "edge.toml"
    for line in HULL_VALUES:
        key = line.split(" = ")[0]
        path.write_text(edited(HULL, line, f"{key} = {toml_value(edge)}"))
        loads_or_one_line(load_hull, path)
    for line in [*PLAN_VALUES, "repeats = 1", "min_r2 = 0.9"]:
        key = line.split(" = ")[0]
        plan = PLAN + "repeats = 1\n[acceptance]\nmin_r2 = 0.9\n"
        path.write_text(edited(plan, line, f"{key} = {toml_value(edge)}"))
        loads_or_one_line(load_campaign_plan, path)
