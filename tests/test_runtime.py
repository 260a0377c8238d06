"""The persistent compilation cache (calib_jax.runtime): where it goes, how it is turned off,
and that an unwritable or corrupt cache never breaks a computation."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from calib_jax.runtime import ENV, cache_dir


def test_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV, str(tmp_path / "c"))
    assert cache_dir() == tmp_path / "c"
    for off in ("off", "0", ""):
        monkeypatch.setenv(ENV, off)
        assert cache_dir() is None
    monkeypatch.delenv(ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "calib_jax" / "jax"


def _run(code: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=300,
    )


PROGRAM = """
    import jax, jax.numpy as jnp
    from calib_jax.runtime import configure
    print(configure())
    f = jax.jit(lambda x: jnp.sum(jnp.sin(x) ** 2))
    print(float(f(jnp.arange(5.0))))
"""
EXPECTED = "2.1275601022845008"  # numpy: float(np.sum(np.sin(np.arange(5.0)) ** 2))


def test_a_corrupt_cache_is_recompiled_not_fatal(tmp_path):
    first = _run(PROGRAM, {ENV: str(tmp_path)})
    assert first.returncode == 0, first.stderr
    assert first.stdout.split()[-1] == EXPECTED
    entries = [p for p in tmp_path.iterdir() if p.is_file() and not p.name.startswith(".")]
    assert entries, "nothing was cached"
    for p in entries:
        p.write_bytes(b"not a compiled executable")
    second = _run(PROGRAM, {ENV: str(tmp_path)})
    assert second.returncode == 0, second.stderr
    assert second.stdout.split()[-1] == EXPECTED


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_an_unwritable_cache_is_skipped(tmp_path):
    tmp_path.chmod(0o500)
    try:
        r = _run(PROGRAM, {ENV: str(tmp_path / "sub")})
    finally:
        tmp_path.chmod(0o700)
    assert r.returncode == 0, r.stderr
    assert "compilation cache off" in r.stdout and r.stdout.split()[-1] == EXPECTED


def test_a_cache_path_that_is_a_file_is_skipped(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    r = _run(PROGRAM, {ENV: str(blocker / "cache")})
    assert r.returncode == 0, r.stderr
    assert "compilation cache off" in r.stdout and r.stdout.split()[-1] == EXPECTED
