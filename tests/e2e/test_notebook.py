"""The example notebook runs top to bottom in a Jupyter kernel (nbclient) and its views display
themselves: a PNG for ``view(...)``, an HTML frame for ``.interactive()``."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOK = ROOT / "examples" / "viewer.ipynb"


def test_the_example_notebook_runs_and_displays_its_views(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    # The kernel is a child process: it imports this checkout.
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(notebook, timeout=240, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError, naming the cell, on any error
    outputs = [output for cell in notebook.cells if cell.cell_type == "code" for output in cell.get("outputs", [])]
    pngs = [o for o in outputs if "image/png" in o.get("data", {})]
    htmls = [o for o in outputs if "text/html" in o.get("data", {})]
    assert len(pngs) >= 2, "view(...) cells display a picture"
    assert any("<iframe srcdoc=" in o["data"]["text/html"] for o in htmls), ".interactive() displays the page"
    assert (tmp_path / "thesis-tank-side.png").stat().st_size > 10_000
    assert (tmp_path / "free-cylinder.png").stat().st_size > 10_000
