"""``tankdaq report``: one self-contained HTML file that a real browser opens (headless Chromium from
Debian's package, driven by playwright) and a PDF that renders to pages (poppler's pdftoppm), both
holding the numbers ``--json`` prints; a rerun gives the same numbers; existing files are refused."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

TANKDAQ = str(Path(sys.executable).with_name("tankdaq"))  # the installed console script
ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = Path("/usr/bin/chromium")
MADE = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e[+-]\d+)?")


def tankdaq(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([TANKDAQ, *args], cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def made(recording: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The report of one recording with a hull that has a scale factor (full scale included) and a
    gyradius its period contradicts (an implausible result, warned), made twice by the same command
    into the same folder: the first moved aside before the second."""
    work = tmp_path_factory.mktemp("report")
    hull = work / "swath_scaled.toml"
    swath = (ROOT / "configs" / "hulls" / "swath.toml").read_text()
    swath = swath.replace("gm_m = 0.08\n", "gm_m = 0.08\nradius_of_gyration_m = 1.0\n", 1)
    hull.write_text(swath + "\n[particulars]\nscale_factor = 12.5\n")
    shutil.copy(recording, work / recording.name)
    args = (
        "report",
        recording.name,
        "--hull",
        hull.name,
        "--full-scale",
        "--model",
        "b1,b3,c1,c3",
        "--out",
        "out",
        "--json",
    )
    first = tankdaq(*args, cwd=work)
    assert first.returncode == 0, first.stderr
    (work / "out").rename(work / "first")
    second = tankdaq(*args, cwd=work)
    assert second.returncode == 0, second.stderr
    return {
        "work": work,
        "args": args,
        "document": json.loads(second.stdout),
        "first": json.loads(first.stdout),
        "html": work / "out" / "report.html",
        "pdf": work / "out" / "report.pdf",
    }


def numeric_cells(document: dict[str, Any]) -> list[float]:
    return [
        cell
        for section in document["sections"]
        for table in section["tables"]
        for row in table["rows"]
        for cell in row
        if isinstance(cell, int | float)
    ]


@pytest.mark.slow
def test_the_report_holds_what_a_reviewer_asks(made: dict[str, Any], recording: Path) -> None:
    """Conditions, coefficients with labelled intervals, B_eq/N, full scale and the provenance: the
    hull file's hash, the recording's hash, the software and the command line."""
    import hashlib

    document = made["document"]
    tables = {t["key"]: t for s in document["sections"] for t in s["tables"]}
    assert {"conditions", "decays", "c1-coefficients", "c1-damping", "c1-full-scale-damping"} <= set(tables)
    assert tables["c1-coefficients"]["intervals"]["± (1σ, fit)"] == "± (1σ, fit)"
    assert set(tables["c1-coefficients"]["intervals"].values()) == {"± (1σ, fit)", "± (95 %, fit)"}
    ship = tables["c1-full-scale-coefficients"]["rows"][0]  # the natural period: model, ship
    assert ship[2] == pytest.approx(ship[1] * 12.5**0.5, rel=1e-5)
    hull_sha = hashlib.sha256((made["work"] / "swath_scaled.toml").read_bytes()).hexdigest()
    assert tables["hulls"]["rows"][0][2] == hull_sha
    assert tables["recordings"]["rows"][0][1] == hashlib.sha256(recording.read_bytes()).hexdigest()
    (warning,) = document["warnings"]  # the period the gyradius contradicts, also beside the numbers
    assert "natural period" in warning
    assert f"warning: {warning.split(': ', 1)[1]}" in document["sections"][1]["notes"]
    about = dict(tables["report"]["rows"])
    assert about["command"] == "tankdaq " + " ".join(made["args"])
    assert about["software"].startswith("tankdaq ")


@pytest.mark.slow
def test_a_rerun_gives_the_same_numbers_and_the_same_page(made: dict[str, Any]) -> None:
    """Everything but the time made is the same: the JSON and the HTML, byte for byte."""
    first, second = dict(made["first"]), dict(made["document"])
    assert MADE.fullmatch(first.pop("made_utc")) and MADE.fullmatch(second.pop("made_utc"))
    assert first == second
    pages = [(made["work"] / d / "report.html").read_text() for d in ("first", "out")]
    assert MADE.sub("T", pages[0]) == MADE.sub("T", pages[1])


@pytest.mark.slow
def test_an_existing_report_is_refused_before_any_work(made: dict[str, Any]) -> None:
    before = made["html"].read_bytes()
    again = tankdaq(*made["args"], cwd=made["work"])
    assert again.returncode == 2
    assert again.stderr.count("\n") == 1 and "exists" in again.stderr and "Traceback" not in again.stderr
    assert made["html"].read_bytes() == before


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("report", "nothing.mcap", "--out", "x"), "nothing.mcap"),
        (("report", "r.mcap"), "--out"),
        (("report", "r.mcap", "--html", "r.txt"), ".html"),
        (("report", "r.mcap", "--runs", "hull=swath", "--out", "x"), "not both"),
    ],
)
@pytest.mark.slow
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, args: tuple[str, ...], says: str) -> None:
    (tmp_path / "r.mcap").write_bytes(b"")
    done = tankdaq(*args, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and says in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Debian's Chromium, headless, through playwright; closed (its processes ended) at the module's end."""
    if not CHROMIUM.is_file():
        pytest.skip("no /usr/bin/chromium (make report-test-deps installs Debian's chromium)")
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="playwright is not installed (the test extra)"
    )
    with sync_api.sync_playwright() as play:
        launched = play.chromium.launch(
            executable_path=str(CHROMIUM), args=["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"]
        )
        try:
            yield launched
        finally:
            launched.close()


READ_TABLES = """() => Object.fromEntries([...document.querySelectorAll('table[data-key]')].map(t => [
    t.dataset.key,
    [...t.querySelectorAll('tbody tr')].map(r => [...r.querySelectorAll('td')].map(c => c.textContent))]))"""


@pytest.mark.slow
def test_the_html_opens_in_chromium_with_the_json_numbers_and_loads_nothing(
    made: dict[str, Any], browser: Any
) -> None:
    page = browser.new_page()
    requested: list[str] = []
    page.on("request", lambda request: requested.append(request.url))
    url = made["html"].resolve().as_uri()
    page.goto(url, wait_until="load")
    shown = page.evaluate(READ_TABLES)
    images = page.evaluate("() => [...document.images].map(i => [i.complete, i.naturalWidth])")
    made_utc = page.text_content("#made-utc")
    warnings = page.eval_on_selector_all("#warning-list li", "items => items.map(i => i.textContent)")
    page.close()
    assert made_utc == made["document"]["made_utc"]
    assert warnings == made["document"]["warnings"] != []
    for section in made["document"]["sections"]:
        for table in section["tables"]:
            rows = shown[table["key"]]
            assert len(rows) == len(table["rows"]), table["key"]
            for cells, texts in zip(table["rows"], rows, strict=True):
                for cell, text in zip(cells, texts, strict=True):
                    if isinstance(cell, int | float):
                        assert float(text) == cell, (table["key"], text, cell)
                    else:
                        assert text == ("–" if cell is None else cell)
    assert images and all(done and width > 100 for done, width in images)  # embedded, decoded
    assert [u for u in requested if u != url and not u.startswith("data:")] == []


@pytest.mark.slow
def test_the_pdf_renders_to_pages_with_the_json_numbers(made: dict[str, Any], tmp_path: Path) -> None:
    from PIL import Image

    if shutil.which("pdftoppm") is None or shutil.which("pdftotext") is None:
        pytest.skip("no pdftoppm/pdftotext (make report-test-deps installs Debian's poppler-utils)")
    subprocess.run(["pdftoppm", "-r", "30", "-png", str(made["pdf"]), str(tmp_path / "page")], check=True)
    pages = sorted(tmp_path.glob("page-*.png"))
    figures = sum(len(s["figures"]) for s in made["document"]["sections"])
    assert len(pages) > figures >= 2
    for page in pages:
        with Image.open(page) as image:
            low, high = image.convert("L").getextrema()
        assert low < 128 < high, f"{page.name} is blank"
    text = subprocess.run(
        ["pdftotext", "-layout", str(made["pdf"]), "-"], check=True, capture_output=True, text=True
    ).stdout
    printed = {float(n) for n in NUMBER.findall(text)}
    missing = [n for n in numeric_cells(made["document"]) if float(n) not in printed]
    assert missing == []
    words = " ".join(text.split())
    for key, value in dict(made["document"]["sections"][-1]["tables"][0]["rows"]).items():
        assert " ".join(value.split()) in words or key == "command"
    assert all(" ".join(line.split()[:8]) in words for line in made["document"]["warnings"])


def test_a_session_folder_reports_its_accepted_decays(recording: Path, tmp_path: Path) -> None:
    """The session's accepted decays, not its rejected ones; the session named in the provenance."""
    from tankdaq.records import DecayEnd
    from tankdaq.report.sources import report_inputs
    from tankdaq.session.checks import Measured
    from tankdaq.session.journal import SessionLog

    for name in ("a.mcap", "b.mcap"):
        shutil.copy(recording, tmp_path / name)
    log = SessionLog(tmp_path)
    measured = dataclasses.asdict(Measured(8.0, 0.0, DecayEnd.SETTLED))
    for decay, (name, verdict) in enumerate([("a.mcap", "rejected"), ("b.mcap", "accepted")], 1):
        log.append("run", decay=decay, draft="T", angle_deg=8.0, file=name, reasons=[], measured=measured)
        log.append("verdict", decay=decay, verdict=verdict)
    found = report_inputs([tmp_path], None, None)
    assert found.files == [tmp_path / "b.mcap"] and found.sessions == [tmp_path]


@pytest.mark.slow
def test_runs_from_the_catalogue_carry_their_ids(recording: Path, tmp_path: Path) -> None:
    import sqlite3

    from tankdaq.report.sources import report_inputs

    shutil.copy(recording, tmp_path / recording.name)
    url = f"sqlite:///{tmp_path / 'catalogue.sqlite'}"
    indexed = tankdaq("catalogue", "index", str(tmp_path), "--catalogue", url, cwd=tmp_path)
    assert indexed.returncode == 0, indexed.stderr
    found = report_inputs([], "hull=swath", url)
    with sqlite3.connect(tmp_path / "catalogue.sqlite") as db:
        (row_id,) = db.execute("select id from decays where path like ?", (f"%{recording.name}",)).fetchone()
    assert found.catalogue_ids == {(tmp_path / recording.name).resolve(): row_id}


def test_a_catalogue_password_never_reaches_the_report() -> None:
    from tankdaq.report.provenance import masked_command

    for argv in (
        ["--catalogue", "postgresql://lab:s3cret@db/tank"],
        ["--catalogue=postgresql://lab:s3cret@db/tank"],
    ):
        line = masked_command(["tankdaq", "report", *argv])
        assert "s3cret" not in line and "db/tank" in line


@pytest.mark.slow
def test_a_budget_plugs_in_as_a_table(tmp_path: Path) -> None:
    """A section made of another helper's DataFrame (an uncertainty budget) is rendered like any other:
    its rows in the HTML and the PDF, its interval labelled."""
    import pandas as pd

    from tankdaq.ident.interval_labels import EXPANDED_U
    from tankdaq.report.content import ReportContent, Section
    from tankdaq.report.html import render_html
    from tankdaq.report.pdf import write_pdf
    from tankdaq.report.slots import budget_table

    frame = pd.DataFrame({"source": ["repeats", "GM"], "value": [0.01, 0.002], "sensitivity": [1.0, 3.5],
                          "contribution": [0.01, 0.007], "share": [0.67, 0.33]})  # fmt: skip
    table = budget_table("c1-budget-period", "the natural period", frame, {"contribution": EXPANDED_U})
    content = ReportContent("t", [Section("c1", "swath T roll", [table])], [], "2026-11-28T12:00:00+00:00")
    page = render_html(content)
    assert (
        'data-key="c1-budget-period"' in page and "[U (k=2, ≈95 %, expanded)]" in page and ">repeats<" in page
    )
    write_pdf(content, tmp_path / "b.pdf")
    if shutil.which("pdftotext") is None:
        pytest.skip("no pdftotext")
    text = subprocess.run(["pdftotext", str(tmp_path / "b.pdf"), "-"], capture_output=True, text=True).stdout
    assert "repeats" in text and "0.007" in text and "expanded" in text
    assert table.to_frame().equals(frame)


def test_a_figure_page_holds_the_figures_own_pixels(tmp_path: Path) -> None:
    """The PDF embeds each figure's PNG as it is (the pixels the HTML shows), not resampled to the page:
    pdfimages reads back the PNG's every pixel."""
    import io

    import numpy as np
    from PIL import Image

    from tankdaq.report.content import Figure, ReportContent, Section
    from tankdaq.report.pdf import write_pdf

    if shutil.which("pdfimages") is None:
        pytest.skip("no pdfimages (make report-test-deps installs Debian's poppler-utils)")
    rng = np.random.default_rng(7)
    pixels = rng.integers(0, 256, size=(60, 90, 3), dtype=np.uint8)  # no two neighbours alike
    png = io.BytesIO()
    Image.fromarray(pixels).save(png, format="png")
    figure = Figure("f", "noise", png.getvalue(), "every pixel its own colour")
    content = ReportContent("t", [Section("s", "figures", figures=[figure])], [], "2026-11-28T12:00:00+00:00")
    write_pdf(content, tmp_path / "f.pdf")
    subprocess.run(["pdfimages", "-png", str(tmp_path / "f.pdf"), str(tmp_path / "img")], check=True)
    (image,) = sorted(tmp_path.glob("img-*.png"))
    with Image.open(image) as read_back:
        # stored bottom row first (the page's transform stands it upright)
        assert np.array_equal(np.asarray(read_back.convert("RGB")), pixels[::-1])


def test_a_command_line_without_a_url_does_not_load_the_catalogue() -> None:
    """The report's command line is masked without importing the catalogue (SQLAlchemy) unless a word
    of it is a URL; a URL's password is still masked."""
    code = (
        "import sys; from tankdaq.report.provenance import masked_command; "
        "print(masked_command(['tankdaq', 'report', 'runs/', '--out', 'x']), 'sqlalchemy' in sys.modules); "
        "print(masked_command(['tankdaq', 'report', '--catalogue', 'postgresql://lab:s3cret@db/tank']))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    plain, masked = done.stdout.splitlines()
    assert plain == "tankdaq report runs/ --out x False"
    assert "s3cret" not in masked and "db/tank" in masked
