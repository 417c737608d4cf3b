"""Queries that say what they did (issue 37, item 7): numbers range-checked and NaN refused, the depth of
``--where`` bounded, dates read as dates (a space or a ``T``, a zone, local time said), ``==`` and an
unclosed quote refused with the right syntax, a value that is not there named beside those that are,
and an empty result with the documented columns. Each on SQLite and a real PostgreSQL server.

The catalogue: four lab CSV decays of swath (T and 1.1T, 4 and 6 deg), indexed, their recorded times
then set to known UTC times around a midnight.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

import tankdaq
from support.catalogue_fresh import fresh_catalogue
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.catalogue.database import BadCatalogueQuery, open_catalogue
from tankdaq.catalogue.query import empty_columns, paths_for
from tankdaq.catalogue.schema import decays
from tankdaq.cli import app
from tankdaq.errors import InputError

#: Each file's recorded time (the stored form: ISO, milliseconds, +00:00).
TIMES = {
    "swath_T_roll_4deg": "2026-11-28T12:00:00.000+00:00",
    "swath_T_roll_6deg": "2026-11-29T00:30:00.000+00:00",
    "swath_1.1T_roll_4deg": "2026-12-01T08:00:00.000+00:00",
    "swath_1.1T_roll_6deg": "2026-12-01T09:00:00.000+00:00",
}
#: The columns the docs' own snippet takes (docs/catalogue.md, "From Python").
DOC_COLUMNS = ["recorded_utc", "release_angle_deg", "b_eq_5deg_per_s", "b44_hat_5deg", "warnings"]


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def catalogue(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The four decays, catalogued once per backend for the module (the tests only read)."""
    folder = tmp_path_factory.mktemp("decays")
    write_simulated_campaign(folder, ["swath"], "roll", [1.0, 1.1], [4.0, 6.0], "csv")
    for url in fresh_catalogue(request, tmp_path_factory.mktemp("catalogue")):
        result = CliRunner().invoke(app, ["catalogue", "index", str(folder), "--catalogue", url])
        assert result.exit_code == 0, result.output
        with open_catalogue(url) as opened, opened.engine.begin() as connection:
            for stem, when in TIMES.items():
                where = decays.c.path.like(f"%{stem}%")
                connection.execute(decays.update().where(where).values(recorded_utc=when))
        yield url


def _runs(url: str, *args: str) -> Result:
    return CliRunner().invoke(app, ["runs", *args, "--catalogue", url])


def _listed(url: str, *args: str) -> list[str]:
    """The files ``runs --json`` lists, by the stem ``TIMES`` knows them by."""
    result = _runs(url, *args, "--json")
    assert result.exit_code == 0, result.output
    return sorted(Path(row["path"]).stem.removesuffix("_run01") for row in json.loads(result.stdout))


def _refused(url: str, *args: str) -> str:
    """The one line of a query refused as usage (exit 2), no traceback."""
    result = _runs(url, *args)
    assert result.exit_code == 2, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    return lines[0]


# ---- numbers ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "where",
    ["decay = 1e30", "size > 1e30", "decay < -1e30", "r2 < nan", "r2 > NaN", "period = inf", "angle = 1e999"],
)
@pytest.mark.slow
def test_a_number_out_of_range_or_not_finite_is_one_line(catalogue: str, where: str) -> None:
    line = _refused(catalogue, "--where", where)
    assert "out of range" in line or "not a finite number" in line, line
    with pytest.raises(BadCatalogueQuery):
        tankdaq.runs(where=where, catalogue=catalogue)


@pytest.mark.slow
def test_numbers_the_columns_hold_still_select(catalogue: str) -> None:
    assert len(_listed(catalogue, "--where", "angle < 1e30 and size < 9223372036854775807")) == 4
    assert _listed(catalogue, "--where", "angle > 5 and size > -9223372036854775807") == [
        "swath_1.1T_roll_6deg",
        "swath_T_roll_6deg",
    ]


@pytest.mark.slow
def test_a_thousand_and_clauses_are_one_line_and_a_hundred_run(catalogue: str) -> None:
    line = _refused(catalogue, "--where", " and ".join(["angle > 1"] * 1000))
    assert "1000 clauses; at most 100" in line
    assert len(_listed(catalogue, "--where", " and ".join(["angle > 1"] * 100))) == 4


# ---- dates --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_date_with_a_space_or_a_t_is_a_time_in_utc(catalogue: str) -> None:
    after_midnight = ["swath_1.1T_roll_4deg", "swath_1.1T_roll_6deg", "swath_T_roll_6deg"]
    assert _listed(catalogue, "--since", "2026-11-28 23:59") == after_midnight
    assert _listed(catalogue, "--since", "2026-11-28T23:59") == after_midnight
    assert _listed(catalogue, "--since", "2026-11-29 00:30:00") == after_midnight
    assert _listed(catalogue, "--since", "2026-11-29 00:30:01Z") == after_midnight[:2]
    assert _listed(catalogue, "--where", 'recorded < "2026-11-28 23:59"') == ["swath_T_roll_4deg"]
    found = paths_for("hull=swath since=2026-11-28T12:00 until=2026-11-29T00:30", catalogue)
    assert [path.stem.removesuffix("_run01") for path in found] == ["swath_T_roll_4deg"]


@pytest.mark.slow
def test_a_zone_or_local_time_is_converted_and_said(catalogue: str, monkeypatch: pytest.MonkeyPatch) -> None:
    zoned = _runs(catalogue, "--since", "2026-11-29 01:00+01:00", "--json")
    assert "since 2026-11-29 01:00+01:00 read as 2026-11-29T00:00:00 UTC" in zoned.stderr
    assert len(json.loads(zoned.stdout)) == 3
    monkeypatch.setenv("TZ", "Europe/Berlin")  # UTC+1 in winter
    time.tzset()
    try:
        local = _runs(catalogue, "--since", "2026-11-29 01:31 local", "--json")
    finally:
        monkeypatch.undo()
        time.tzset()
    assert "since 2026-11-29 01:31 local read as 2026-11-29T00:31:00 UTC" in local.stderr
    assert len(json.loads(local.stdout)) == 2


@pytest.mark.parametrize("since", ["2026-11-31", "28.11.2026", "2026-11-28 25:00", "2026-11-28 +01:00"])
@pytest.mark.slow
def test_a_date_that_is_not_one_is_one_line_that_says_utc(catalogue: str, since: str) -> None:
    line = _refused(catalogue, "--since", since)
    assert f"date {since!r}" in line and ("UTC" in line or "needs a time" in line), line


# ---- the language's slips -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("where", "advice"),
    [
        ("hull==swath", "write hull = swath (one =)"),
        ("hull == swath", "write hull = swath (one =)"),
        ("r2 => 0.99", "write r2 >= 0.99"),
        ('hull = "swath', 'a quote " is not closed; quote a value whole'),
        ("plan = 'trial 2", "a quote ' is not closed"),
        ('hull = swath and plan = "a', "is not closed"),
    ],
)
@pytest.mark.slow
def test_double_equals_and_an_unclosed_quote_are_refused_with_the_right_syntax(
    catalogue: str, where: str, advice: str
) -> None:
    assert advice in _refused(catalogue, "--where", where)


@pytest.mark.slow
def test_runs_with_double_equals_is_refused_and_a_quoted_and_is_one_value(catalogue: str) -> None:
    with pytest.raises(BadCatalogueQuery, match=r"write hull=swath \(one ="):
        paths_for("hull==swath", catalogue)
    quoted = _runs(catalogue, "--where", 'plan = "trial and error" and hull = swath')
    assert quoted.exit_code == 0, quoted.output
    assert "no plan 'trial and error'; no run has a plan" in quoted.stderr


# ---- a value that is not there ------------------------------------------------------------------------


@pytest.mark.slow
def test_a_value_that_is_not_there_names_the_values_that_are(catalogue: str) -> None:
    result = _runs(catalogue, "--hull", "SWATH")
    assert result.exit_code == 0
    assert result.stderr.splitlines()[:2] == ["no hull 'SWATH'; the catalogue holds: swath", "0 run(s)"]
    drafts = _runs(catalogue, "--where", "draft = 0.9T")
    assert "no draft '0.9T'; the catalogue holds: 1.1T, T" in drafts.stderr
    with pytest.warns(UserWarning, match="no hull 'kvlcc2'; the catalogue holds: swath"):
        assert tankdaq.runs(hull="kvlcc2", catalogue=catalogue).empty
    with pytest.raises(BadCatalogueQuery, match="no hull 'kvlcc2'; the catalogue holds: swath"):
        paths_for("hull=kvlcc2", catalogue)
    held = _runs(catalogue, "--hull", "swath", "--since", "2030")  # there, but not then: nothing to name
    assert held.exit_code == 0 and "no hull" not in held.stderr and "0 run(s)" in held.stderr


# ---- an empty result ----------------------------------------------------------------------------------


@pytest.mark.slow
def test_an_empty_result_has_the_documented_columns(catalogue: str) -> None:
    full = tankdaq.runs(hull="swath", catalogue=catalogue)
    empty = tankdaq.runs(hull="swath", since="2030", catalogue=catalogue)
    assert len(full) == 4 and empty.empty
    assert empty[DOC_COLUMNS].empty  # the docs' own snippet, on nothing found
    assert list(empty.columns) == empty_columns()
    assert set(empty.columns) <= set(full.columns)
    extra = set(full.columns) - set(empty.columns)  # only the fitted terms, which come with a fit
    assert all(name.endswith(("_ci_low", "_ci_high")) or f"{name}_ci_low" in full.columns for name in extra)
    assert not {"recorded_utc", "hull", "path", "b44_hat_5deg"} & extra

    header = _runs(catalogue, "--hull", "swath", "--since", "2030", "--csv").stdout.splitlines()
    assert header == [",".join(empty_columns())]
    exported = tankdaq.runs(hull="swath", since="2030", catalogue=catalogue, exports=True)
    assert {"export", "format", "decay", "recording"} <= set(exported.columns) and exported.empty
    exports_csv = _runs(catalogue, "--since", "2030", "--exports", "--csv").stdout.splitlines()
    assert exports_csv == [",".join(empty_columns(exports=True))]


@pytest.mark.slow
def test_a_value_no_backend_binds_is_one_line_and_recorded_contains_is_text(catalogue: str) -> None:
    assert "holds a NUL character" in _refused(catalogue, "--where", "plan = trial\x002")
    assert "not text (UTF-8)" in _refused(catalogue, "--hull", "sw\udcffath")  # undecodable argv bytes
    assert _listed(catalogue, "--where", "recorded ~ T00:30") == ["swath_T_roll_6deg"]


@pytest.mark.slow
def test_from_python_a_filter_that_is_not_text_is_refused_by_name(catalogue: str, tmp_path: Path) -> None:
    for given, name in ((dict(hull=123), "hull"), (dict(where=0.99), "where"), (dict(fits=[1]), "fits")):
        with pytest.raises(InputError, match=f"^{name}\\W.*give "):
            tankdaq.runs(catalogue=catalogue, **given)
    # a year as a number is the year (api.arguments.when), as "2026" is
    by_number = tankdaq.runs(catalogue=catalogue, since=2026)
    assert by_number.equals(tankdaq.runs(catalogue=catalogue, since="2026"))
    if catalogue.startswith("sqlite:///"):  # a pathlib.Path is a path
        assert len(tankdaq.runs(catalogue=Path(catalogue.removeprefix("sqlite:///")))) == 4
