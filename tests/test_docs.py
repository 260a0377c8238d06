"""Issue 18: the documentation site builds from the docstrings and docs/ pages with mkdocs
--strict, so a broken link, a missing page or an API reference to a name that no longer exists
fails here (checked by hand: a `::: calib_jax.io.files.iter_rowz` page aborts the build with
"Could not collect", a link to a missing page aborts it in strict mode). The pages' Python
blocks run in tests/test_readme_examples.py."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocstrings")
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent)) or shutil.which("mkdocs")
    if mkdocs is None:
        pytest.skip("mkdocs is not installed (pip install -e '.[test]')")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    r = subprocess.run(
        [mkdocs, "build", "--strict", "-d", str(tmp_path / "site")],
        cwd=ROOT, capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    page = (tmp_path / "site" / "api" / "results" / "index.html").read_text()
    # the API page holds the docstrings: a field's doc and a method's
    assert "Outcome of" in page and "Paper 1 Table 1 layout" in page
    assert (tmp_path / "site" / "formats" / "index.html").exists()


def test_performance_tables_are_their_benchmark_json():
    """docs/performance.md's batch tables are written from the committed JSON by
    benchmarks/tables.py: a re-run benchmark without its table, or a number edited by hand,
    fails here (the hand-written table had dropped the 10,000-sensor sharded row)."""
    import importlib.util

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("tables", root / "benchmarks" / "tables.py")
    tables = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tables)
    text = (root / "docs" / "performance.md").read_text()
    assert tables.render(text) == text, "run .venv/bin/python benchmarks/tables.py"
    for doc, made in tables.OTHER_TABLES.items():  # close_the_loop.md's honest-error table
        text = doc.read_text()
        assert tables.render(text, tables=made) == text, f"{doc.name}: run benchmarks/tables.py"
    # not vacuous: a changed number in the JSON changes the table
    results = root / "benchmarks" / "results"
    assert "| 1000 | H200 | 0.00593 |" in tables.batch_gpu(results)
