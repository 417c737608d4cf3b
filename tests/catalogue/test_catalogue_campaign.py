"""A campaign over files the run catalogue does not hold yet: each file's row is made by the worker that
scans the file and sent back with the scan, so the campaign's own process only writes it; the rows are
the ones ``tankdaq catalogue index`` makes of the same files.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa
from typer.testing import CliRunner

import tankdaq
from tankdaq.campaign.stream import FileWork
from tankdaq.campaign.synthetic import write_simulated_campaign
from tankdaq.catalogue.database import open_catalogue, resolve_url
from tankdaq.catalogue.hooks import CatalogueWriter
from tankdaq.catalogue.rows import find_hull, hull_version, worker_row
from tankdaq.catalogue.schema import PATH_INDEXES, SCHEMA_VERSION, decays, hulls, schema_version
from tankdaq.cli import app
from tankdaq.config import validation
from tankdaq.config.hulls import load_hull
from tankdaq.store.export import export_recording

runner = CliRunner()
#: What differs between two catalogues of the same files: when each row was written, its number and its
#: reference fit's.
WHEN = ("id", "created_utc", "updated_utc", "first_seen_utc", "reference_fit_id")


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``old/``: two recordings a catalogue may already hold; ``new/``: two more, a lab's CSV decay and
    a CSV exported from a recording (a copy of its decay, never a row of its own)."""
    folder = tmp_path_factory.mktemp("lab")
    write_simulated_campaign(folder / "old", ["swath"], "roll", [1.0], [4.0, 6.0], "mcap")
    (recording, _) = write_simulated_campaign(folder / "new", ["swath"], "roll", [1.1], [4.0, 6.0], "mcap")
    write_simulated_campaign(folder / "new", ["swath"], "roll", [0.9], [5.0], "csv", seed=1)
    export_recording(recording, "csv", folder / "new" / "exported")
    return folder


def _table(url: str, table: sa.Table) -> list[dict[str, Any]]:
    """A table's rows without when they were written, by path (decays) or hash (hulls)."""
    with open_catalogue(str(resolve_url(url))) as catalogue, catalogue.reading() as connection:
        rows = [
            {k: v for k, v in r._mapping.items() if k not in WHEN}
            for r in connection.execute(sa.select(table))
        ]
    return sorted(rows, key=lambda row: str(row.get("path", row["sha256"])))


def _invoke(*args: object) -> str:
    result = runner.invoke(app, [str(arg) for arg in args])
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.mark.slow
def test_a_campaigns_rows_of_files_not_catalogued_are_the_rows_index_makes(
    lab: Path, tmp_path: Path, catalogue_url: str
) -> None:
    campaign = ["campaign", lab, "--model", "b1,c1", "--jobs", "2", "--catalogue"]
    by_campaign, by_index = catalogue_url, f"sqlite:///{tmp_path / 'index.sqlite'}"
    _invoke("catalogue", "index", lab / "old", "--catalogue", by_campaign)  # two rows there, five not
    _invoke(*campaign, by_campaign)
    _invoke("catalogue", "index", lab, "--catalogue", by_index)
    _invoke(*campaign, by_index)

    made = _table(by_campaign, decays)
    assert [Path(row["path"]).name for row in made] == [
        "swath_0.9T_roll_5deg_run01.csv",
        "swath_1.1T_roll_4deg_run01.mcap",
        "swath_1.1T_roll_6deg_run01.mcap",
        "swath_T_roll_4deg_run01.mcap",
        "swath_T_roll_6deg_run01.mcap",
    ]  # by path: new/ then old/; the exported CSV is no decay of its own
    assert {row["fit_source"] for row in made} == {"campaign"}
    assert made == _table(by_index, decays)
    assert _table(by_campaign, hulls) == _table(by_index, hulls)


def _made_here(path: Path, sha256: str) -> tuple[dict[str, Any], dict[str, Any] | None, int] | None:
    """``worker_row``, and the process that made it."""
    made = worker_row(path, sha256)
    return None if made is None else (*made, os.getpid())


@pytest.mark.slow
def test_the_rows_are_made_by_the_workers_for_the_files_not_catalogued_only(
    lab: Path, tmp_path: Path
) -> None:
    if validation.usable_cores() < 2:
        pytest.skip("one usable core: a campaign runs in its own process, with no worker to make a row")
    folder = tmp_path / "lab"
    shutil.copytree(lab, folder)
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    _invoke("catalogue", "index", folder / "old", "--catalogue", url)
    lines: list[str] = []
    writer = CatalogueWriter(url, lines.append)
    rows = writer.file_rows()
    makers: list[int] = []
    taken: list[str] = []

    def take(made: list[tuple[dict[str, Any], dict[str, Any] | None, int]]) -> None:
        makers.extend(pid for _, _, pid in made)
        taken.extend(Path(row["path"]).name for row, _, _ in made)
        rows.take([(row, version) for row, version, _ in made])

    with writer:
        tankdaq.campaign(
            folder, "b1,c1", jobs=2, on_result=lambda r: writer.add_campaign([r]),
            file_work=FileWork(rows.wanted, _made_here, take),
        )  # fmt: skip
    assert sorted(taken) == [
        "swath_0.9T_roll_5deg_run01.csv",
        "swath_1.1T_roll_4deg_run01.mcap",
        "swath_1.1T_roll_6deg_run01.mcap",
    ]
    assert makers and os.getpid() not in makers  # made where the file was read, not here
    assert lines == []
    written = _table(url, decays)
    assert len(written) == 5 and {row["fit_source"] for row in written} == {"campaign"}


@pytest.mark.slow
def test_a_catalogue_that_cannot_answer_asks_for_no_rows_in_one_line(lab: Path, tmp_path: Path) -> None:
    corrupt = tmp_path / "corrupt.sqlite"
    corrupt.write_bytes(b"this is not a database " * 400)
    lines: list[str] = []
    with CatalogueWriter(f"sqlite:///{corrupt}", lines.append) as writer:
        assert writer.uncatalogued(sorted(lab.rglob("*.mcap"))) == []
    assert len(lines) == 1 and lines[0].startswith("catalogue: ") and "index" in lines[0]


def test_a_hull_file_that_changed_is_read_anew_even_at_the_same_size(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Rows find each decay's hull once per content: a GM changed in place (same size, same second) is
    the new hull, in the row's B̂44 and in its hull version alike."""
    monkeypatch.setenv("TANKDAQ_HULLS_DIR", str(tmp_path))
    shipped = Path(str(load_hull("swath").path)).read_text()
    assert "gm_m = 0.08\n" in shipped
    mine = tmp_path / "swath.toml"
    mine.write_text(shipped)
    first = find_hull("swath")
    assert first is not None and first.path == mine and find_hull("swath") is first  # parsed once
    mine.write_text(shipped.replace("gm_m = 0.08\n", "gm_m = 0.09\n"))
    second = find_hull("swath")
    assert second is not None and second is not first
    assert (first.particulars("roll").gm_m, second.particulars("roll").gm_m) == (0.08, 0.09)
    assert hull_version(second)["sha256"] == hashlib.sha256(mine.read_bytes()).hexdigest()


def test_a_catalogue_of_schema_2_gets_its_path_indexes_when_opened(tmp_path: Path) -> None:
    """A fit is written onto its rows by path: a catalogue written before the path indexes gets them."""
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    with open_catalogue(url) as catalogue, catalogue.engine.begin() as connection:  # back to version 2
        for index in PATH_INDEXES:
            index.drop(connection)
        connection.execute(schema_version.delete().where(schema_version.c.version > 2))
    with open_catalogue(url) as catalogue, catalogue.reading() as connection:
        inspector = sa.inspect(connection)
        names = {found["name"] for table in ("decays", "exports") for found in inspector.get_indexes(table)}
        version = connection.execute(sa.select(sa.func.max(schema_version.c.version))).scalar()
    assert {"ix_decays_path", "ix_exports_source_path"} <= names and version == SCHEMA_VERSION
