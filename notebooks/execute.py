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
    _drop_font_warnings(nb)
    nbformat.validate(nb)
    nbformat.write(nb, path)
    print(f"{path.name}: executed in {time.perf_counter() - t0:.1f} s, written")


def _drop_font_warnings(nb) -> None:
    """Remove matplotlib's "findfont: ... not found" lines from stderr outputs: they say which
    fonts this machine lacks, not what the notebook computed (21 of them on 2026-11-28)."""
    for cell in nb.cells:
        kept = []
        for out in cell.get("outputs", []):
            if out.output_type == "stream" and out.name == "stderr":
                lines = [x for x in out.text.splitlines(True) if not x.startswith("findfont:")]
                if not lines:
                    continue
                out.text = "".join(lines)
            kept.append(out)
        if cell.cell_type == "code":
            cell.outputs = kept


if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    for p in [Path(a) for a in sys.argv[1:]] or sorted(here.glob("*.ipynb")):
        execute(p)
