"""Every Python block of README.md and docs/**/*.md runs as written (issue 13: the README's
own examples raised). The blocks of one file run in order in one namespace, as a reader would
paste them into one notebook, in a temporary working directory (they write files)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks(path: Path) -> list[str]:
    return _BLOCK.findall(path.read_text())


def test_the_readme_has_python_examples():
    # guards the extraction itself: a changed fence style must not silently run nothing
    assert len(python_blocks(ROOT / "README.md")) >= 3
    assert all(python_blocks(ROOT / "docs" / p) for p in ("pipeline.md", "batches.md"))


@pytest.mark.parametrize(
    "path", [p for p in DOCS if python_blocks(p)], ids=lambda p: str(p.relative_to(ROOT))
)
def test_python_blocks_run_as_written(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    for i, block in enumerate(python_blocks(path)):
        code = compile(block, f"{path.name}[python block {i + 1}]", "exec")
        exec(code, namespace)  # noqa: S102 - the documentation's own examples
