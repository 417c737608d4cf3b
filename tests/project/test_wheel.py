"""The built wheel, installed read-only, works from another folder (issue 23's must-hold).

The wheel is built from this tree, installed without its dependencies into a fresh venv whose
site-packages is then made read-only; the dependencies come from this project's venv through a plain
path line in a ``.pth`` file (nested ``.pth`` files there are not processed, so this checkout's editable
install stays out: ``tankdaq.__file__`` says which one runs). With a fresh home folder and from another
folder, ``tankdaq demo`` builds its kernels into the user cache (drawing its progress) and passes,
``tankdaq --help`` and ``help(tankdaq)`` work, and nothing is written into site-packages (root ignores
the read-only bits: the listing before and after is what holds it). The wheel carries the LICENSE and
a PyPI page that starts with ``pip install``.
"""

from __future__ import annotations

import os
import pty
import re
import shutil
import stat
import subprocess
import sys
import sysconfig
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from support.doc_examples import PIP_PAGE, examples, problem, run, shell_env
from tankdaq.ident.compiled import kernel_folder

ROOT = Path(__file__).resolve().parents[2]

#: Variables that would steer where tankdaq looks or writes: the installed copy sees none of them.
STEERING = (
    "TANKDAQ_CACHE_DIR",
    "TANKDAQ_KERNEL_DIR",
    "TANKDAQ_CONFIG_DIR",
    "TANKDAQ_HULLS_DIR",
    "NUMBA_CACHE_DIR",
    "XDG_CACHE_HOME",
    "XDG_CONFIG_HOME",
    "PYTHONPATH",
)

#: Which tankdaq runs, its help and the public API's ``tankdaq.identify``'s.
HELP = """
import tankdaq
print("file:", tankdaq.__file__)
help(tankdaq)
help(tankdaq.identify)
"""


def _listing(folder: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``folder`` with its size and modification time (ns)."""
    return {
        str(path.relative_to(folder)): (path.stat().st_size, path.stat().st_mtime_ns)
        for path in folder.rglob("*")
    }


def _on_a_terminal(args: list[str | Path], cwd: Path, env: dict[str, str]) -> tuple[int, str, str]:
    """Run ``args`` with stderr on a pseudo-terminal (where progress is drawn): (exit code, stdout,
    stderr without its terminal control sequences)."""
    master, slave = pty.openpty()
    drawn = bytearray()

    def drain() -> None:
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the other side closed: the process has ended
                return
            if not chunk:
                return
            drawn.extend(chunk)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    try:
        done = subprocess.run(
            args, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=slave, text=True, timeout=600
        )
    finally:
        os.close(slave)
        reader.join(timeout=30)
        os.close(master)
    plain = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", drawn.decode(errors="replace"))
    return done.returncode, done.stdout, plain.replace("\r", "\n")


def _writable_again(folder: Path) -> None:
    for path in [folder, *folder.rglob("*")]:
        path.chmod(path.stat().st_mode | stat.S_IWUSR)


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Path]]:
    """(venv, its site-packages): the wheel of this tree installed alone, site-packages read-only (once
    for the module: the wheel is built once)."""
    tmp_path = tmp_path_factory.mktemp("wheel")
    dist = tmp_path / "dist"
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", dist, ROOT],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert built.returncode == 0, built.stderr
    (wheel,) = dist.glob("tankdaq-*.whl")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", venv], check=True, timeout=120)
    python = venv / "bin" / "python"
    install = [sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "--no-index", "-q"]
    done = subprocess.run([*install, wheel], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    site = Path(
        subprocess.run(
            [python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        ).stdout.strip()
    )
    (site / "_project_dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")
    for path in [site, *site.rglob("*")]:
        path.chmod(path.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    try:
        yield venv, site
    finally:
        _writable_again(site)


@pytest.mark.slow
def test_the_wheel_installed_read_only_runs_the_demo_from_another_folder(
    installed: tuple[Path, Path], tmp_path: Path
) -> None:
    venv, site = installed
    before = _listing(site)
    home, work = tmp_path / "home", tmp_path / "work"
    home.mkdir()
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in STEERING} | {"HOME": str(home)}

    def run(*args: str | Path) -> subprocess.CompletedProcess[str]:
        return subprocess.run(args, cwd=work, env=env, capture_output=True, text=True, timeout=600)

    (info,) = site.glob("tankdaq-*.dist-info")
    assert "MIT License" in (info / "licenses" / "LICENSE").read_text()
    page = (info / "METADATA").read_text().split("\n\n", 1)[1]  # the long description, after the headers
    assert page.index("pip install dist/tankdaq-") < page.index("tankdaq demo") and "make demo" not in page
    assert "](https://" in page and "](docs/" not in page, "the PyPI page links to files not in the wheel"

    helped = run(venv / "bin" / "python", "-c", HELP)
    assert helped.returncode == 0, helped.stderr
    assert f"file: {site / 'tankdaq' / '__init__.py'}" in helped.stdout, "not the installed copy"
    assert "Help on package tankdaq" in helped.stdout
    assert "Help on function identify" in helped.stdout, helped.stdout[-2000:]  # the public API

    usage = run(venv / "bin" / "tankdaq", "--help")
    assert usage.returncode == 0, usage.stderr
    assert "demo" in usage.stdout

    code, shown, said = _on_a_terminal(
        # the truth's own terms, so every coefficient is checked against its truth (the default model,
        # chosen by the data, is the demo's in test_one_model)
        [
            venv / "bin" / "tankdaq",
            "demo",
            "--runs",
            "1",
            "--out",
            "demo",
            "--model",
            "seed001-eq1",
            "--seed",
            "0",
        ],  # the same decay every run
        work,
        env,
    )
    assert code == 0, said[-3000:]
    assert "Traceback" not in said
    assert _listing(site) == before, "something was written into the read-only site-packages"
    assert "building native kernels (once, about" in said and "MB) into ~/.cache/tankdaq/kernels" in said
    assert re.search(r"building native kernels .* 0:00:\d\d", said), "no progress with the elapsed time"
    assert "numba's JIT" not in said, said[-3000:]
    built = list((home / ".cache" / "tankdaq" / "kernels").glob("tankdaq_kernels-*"))
    assert len(built) == 1, built
    truth = [line for line in shown.splitlines() if "vs" in line and "95 % interval" in line]
    assert truth and all("(inside" in line for line in truth), shown
    assert len(list((work / "demo").glob("*.mcap"))) == 1
    assert len(list((work / "demo").glob("*.png"))) == 1


@pytest.mark.slow
@pytest.mark.timeout(1800)  # the demo, a particle swarm, a campaign and a diagnosis, from the wheel
def test_every_command_of_the_pypi_page_runs_as_written_from_the_wheel(
    installed: tuple[Path, Path], tmp_path: Path
) -> None:
    """docs/pypi.md, block by block, in a pip user's folder holding the wheel in ``dist/`` (its ``pip
    install`` lines resolved with ``--dry-run``); ``tankdaq docs`` prints the pages from the wheel."""
    venv, site = installed
    before = _listing(site)
    work, home = tmp_path / "work", tmp_path / "home"
    (work / "dist").mkdir(parents=True)
    home.mkdir()
    (wheel,) = (site.parents[3] / "dist").glob("tankdaq-*.whl")  # venv/lib/pythonX.Y/site-packages
    shutil.copy(wheel, work / "dist" / wheel.name)
    env = shell_env(venv, home) | {"TANKDAQ_KERNEL_DIR": str(kernel_folder())}  # built by the test above
    env["PATH"] += os.pathsep + str(Path(sys.executable).parent)  # pip: the venv has none of its own
    page = [e for e in examples(ROOT) if e.page == PIP_PAGE]
    assert [e.kind for e in page][:2] == ["pip", "pip"] and any(e.marker == "[hardware]" for e in page)
    wrong = [said for e in page if (said := problem(e, run(e, work, env))) is not None]
    assert not wrong, "\n\n".join(wrong)
    listed = run(next(e for e in page if e.text == "tankdaq docs"), work, env).out
    assert f"pages in {site / 'tankdaq' / '_docs'}" in listed and "catalogue " in listed
    models = run(next(e for e in page if e.text == "tankdaq docs models"), work, env).out
    assert models.startswith("# ") and "Plausibility checks" in models
    copied = {path.name for path in (work / "examples").iterdir()}
    assert {"decay_in_a_notebook.ipynb", "kvlcc2_roll_decay.csv"} <= copied
    unknown = subprocess.run(
        [venv / "bin" / "tankdaq", "docs", "nosuchpage"], cwd=work, env=env, capture_output=True, text=True
    )
    assert unknown.returncode == 2 and unknown.stderr.count("\n") == 1 and "catalogue, " in unknown.stderr
    assert _listing(site) == before
