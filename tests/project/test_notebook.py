"""The example notebook runs (issue 23's must-hold): it reads a recording into a DataFrame with units,
identifies it through ``tankdaq.identify`` with the numbers of ``tankdaq identify --json``, and writes CSV
and HDF5 that ``pd.read_csv`` and h5py read back exactly (its own cells assert that).

Executed with nbclient on an ipykernel of this interpreter (a kernelspec written into a temporary
JUPYTER_PATH, so the notebook runs in the same environment as the suite), in a temporary folder.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat", reason="the notebook runner is in the test extra")
nbclient = pytest.importorskip("nbclient", reason="the notebook runner is in the test extra")
pytest.importorskip("ipykernel", reason="the notebook runs on an ipykernel of this interpreter")

NOTEBOOK = Path(__file__).resolve().parents[2] / "examples" / "decay_in_a_notebook.ipynb"
KERNEL = "tankdaq-test-python"


def kernel_here(folder: Path) -> None:
    """A kernelspec whose kernel is this interpreter (its ipykernel), in ``folder/kernels``."""
    spec = folder / "kernels" / KERNEL
    spec.mkdir(parents=True)
    argv = [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
    document = {"argv": argv, "display_name": "tankdaq tests", "language": "python"}
    (spec / "kernel.json").write_text(json.dumps(document))


def test_the_notebook_is_stored_without_outputs() -> None:
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert code and all(cell.outputs == [] and cell.execution_count is None for cell in code)


@pytest.mark.slow
def test_the_notebook_identifies_as_the_cli_and_round_trips_its_exports(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    kernel_here(tmp_path / "jupyter")
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    work = tmp_path / "work"
    work.mkdir()
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(
        notebook, kernel_name=KERNEL, timeout=180, resources={"metadata": {"path": str(work)}}
    )
    client.execute()  # a failing cell (its own exactness asserts included) raises CellExecutionError

    printed = "".join(output.get("text", "") for cell in notebook.cells for output in cell.get("outputs", []))
    assert "CSV: all 15 columns equal the recording's samples" in printed
    assert "HDF5: all 15 datasets equal the CSV, units alike" in printed
    shown = [output.data for cell in notebook.cells for output in cell.get("outputs", []) if "data" in output]
    assert any("roll_deg" in data.get("text/html", "") for data in shown)  # the samples, units in names
    assert any("image/png" in data for data in shown)  # result.plot()

    (recording,) = (work / "notebook-recordings").glob("*.mcap")
    command = Path(sys.executable).with_name("tankdaq")
    done = subprocess.run(
        [str(command), "identify", "--json", "--hull", "swath", str(recording.relative_to(work))],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=work,
    )
    assert done.returncode == 0, done.stderr
    by_cli = json.loads(done.stdout)
    in_notebook = json.loads((work / "identify.json").read_text())
    assert by_cli.pop("elapsed_s") > 0 and in_notebook.pop("elapsed_s") > 0  # wall time: never equal
    assert in_notebook == by_cli
    assert all(row["b44_hat"] > 0 for row in in_notebook["b_eq"])
    exported = sorted(path.name for path in (work / "exports").iterdir())
    assert exported == [f"{recording.stem}.{suffix}" for suffix in ("csv", "h5", "json")]
