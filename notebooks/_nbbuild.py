"""Shared by the notebook build scripts: assemble cells, execute them, write the notebook."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook


def recorder(cells: list[tuple[str, str]]):
    """(md, code): functions that append a markdown or code cell to ``cells``."""

    def md(text: str) -> None:
        cells.append(("markdown", text.strip("\n")))

    def code(text: str) -> None:
        cells.append(("code", text.strip("\n")))

    return md, code


def build(cells: list[tuple[str, str]]) -> nbformat.NotebookNode:
    nb = new_notebook()
    nb.metadata["kernelspec"] = {
        "display_name": "Python 3",
        "language": "python",
        "name": "python3",
    }
    nb.metadata["language_info"] = {"name": "python"}
    for kind, text in cells:
        nb.cells.append(new_markdown_cell(text) if kind == "markdown" else new_code_cell(text))
    return nb


def run(cells: list[tuple[str, str]], out: Path) -> None:
    """Execute in a temporary directory (as the test suite does) and write with outputs."""
    nb = build(cells)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        NotebookClient(
            nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": tmp}}
        ).execute()
    print(f"executed in {time.perf_counter() - t0:.1f} s")
    nbformat.validate(nb)
    nbformat.write(nb, out)
    print(f"wrote {out}")
