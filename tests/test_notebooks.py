"""The notebooks run top to bottom (they are documentation that must stay true)."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    # notebook 05 takes every 6th row of its BROAD excerpts here (48 Hz; the kernel inherits
    # this): its end-to-end fits on every 3rd row took 60 of its 105 s, on every 6th 30 s
    monkeypatch.setenv("CALIB_JAX_NB_STEP", "6")
    # notebook 07 calibrates a fleet of 100 simulated logs here (1,000 when run by hand)
    monkeypatch.setenv("CALIB_JAX_NB_FLEET", "100")
    nb = nbformat.read(path, as_version=4)
    NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    ).execute()
    errors = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.get("outputs", [])
        if o.output_type == "error"
    ]
    assert not errors
