"""Re-execute notebooks in place, keeping their outputs: the .ipynb files are the sources
(edit them in Jupyter or any editor; ``ruff check`` and ``ruff format`` cover them, and
``tests/test_notebooks.py`` runs them).

Run: ``.venv/bin/python notebooks/execute.py [NOTEBOOK ...]`` (default: every notebook here).
Each runs in a temporary working directory, as the tests run it.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient


def execute(path: Path) -> None:
    nb = nbformat.read(path, as_version=4)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        NotebookClient(
            nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": tmp}}
        ).execute()
    nbformat.validate(nb)
    nbformat.write(nb, path)
    print(f"{path.name}: executed in {time.perf_counter() - t0:.1f} s, written")


if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    for p in [Path(a) for a in sys.argv[1:]] or sorted(here.glob("*.ipynb")):
        execute(p)
