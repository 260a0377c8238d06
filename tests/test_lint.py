"""Lint and annotations: CI runs the README's test command, so the checks a reviewer would run
by hand run here."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import shutil
import subprocess
import sys
import typing
from pathlib import Path

import pytest

import calib_jax

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_check_passes():
    """ruff (pinned in pyproject's test extra) with the project's rules, notebooks included."""
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]')")
    r = subprocess.run([ruff, "check", "."], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_notebooks_are_ruff_formatted():
    """The .ipynb files are the notebooks' sources (no string builders): their code cells are
    formatted as the package is (``ruff format notebooks/`` fixes a failure)."""
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]')")
    r = subprocess.run(
        [ruff, "format", "--check", "notebooks"], cwd=ROOT, capture_output=True, text=True
    )
    assert r.returncode == 0, r.stdout + r.stderr


def _modules():
    for info in pkgutil.walk_packages(calib_jax.__path__, "calib_jax."):
        yield importlib.import_module(info.name)


def test_every_annotation_evaluates():
    """jaxtyping annotations such as Float[Array, 3] raise when evaluated (the shape must be a
    string); with postponed annotations that only shows when someone inspects them, as
    jaxtyping's runtime checker or a documentation builder does."""
    bad = []
    for mod in _modules():
        for name, obj in vars(mod).items():
            if getattr(obj, "__module__", None) != mod.__name__:
                continue
            targets = [obj]
            if inspect.isclass(obj):
                targets += [v for v in vars(obj).values() if inspect.isfunction(v)]
            for t in targets:
                if not (inspect.isclass(t) or inspect.isfunction(t)):
                    continue
                try:
                    typing.get_type_hints(t)
                except Exception as exc:  # noqa: BLE001 - every failure is reported
                    bad.append(f"{mod.__name__}.{name}: {type(exc).__name__}: {exc}")
    assert not bad, "\n".join(bad)
