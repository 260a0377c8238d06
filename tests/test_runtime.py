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


# A whole fit kept on disk (runtime.DiskJit): an LM fit of a line, whose result is an equinox
# module (LMResult), the case JAX's own tree serialization cannot load.
FIT_PROGRAM = """
    import sys
    import jax.numpy as jnp
    from calib_jax.runtime import configure, disk_jit
    from calib_jax.lm import lm_solve
    print(configure())

    def fit(x, y):
        return lm_solve(lambda p, d: p[0] * d[0] + p[1] - d[1], jnp.zeros(2), (x, y))

    x = jnp.linspace(0.0, 1.0, 20)
    res = disk_jit(fit, "test.line")(x, 2.0 * x + 1.0 + 0.01 * jnp.sin(40 * x))
    print(type(res).__name__, int(res.status), repr(float(res.params[0])), float(res.stderr[1]))
"""


def test_a_fit_kept_on_disk_is_reloaded_whole_and_survives_corruption(tmp_path):
    """The second process loads the exported program (the file is not rewritten) and gets the
    same result bit for bit: the same program compiles to the same executable. A corrupt file
    is exported again, not fatal."""
    runs = []
    for k in range(3):
        if k == 2:
            for p in (tmp_path / "aot").iterdir():
                p.write_bytes(b"not an exported program")
        r = _run(FIT_PROGRAM, {ENV: str(tmp_path)})
        assert r.returncode == 0, r.stderr
        assert "Traceback" not in r.stderr and "cache skipped" not in r.stderr, r.stderr
        files = sorted((tmp_path / "aot").iterdir())
        assert len(files) == 1
        runs.append((r.stdout.splitlines()[-1], files[0].stat().st_mtime_ns, files[0].read_bytes()))
    assert runs[0][0].startswith("LMResult ")
    assert runs[0][0] == runs[1][0] == runs[2][0]
    assert runs[1][1] == runs[0][1]  # loaded, not exported again
    assert runs[2][2] == runs[0][2]  # the corrupt file was replaced by the same program


def test_disk_jit_under_a_transformation_is_plain_jit(tmp_path, monkeypatch):
    """Inside vmap (tracers) nothing is read or written; the answer is jax.jit's."""
    import jax
    import jax.numpy as jnp

    from calib_jax import runtime

    monkeypatch.setattr(runtime, "_AOT_DIR", [tmp_path / "aot"])
    f = runtime.disk_jit(lambda x: {"s": jnp.sum(x**2)}, "test.square")
    xs = jnp.arange(6.0).reshape(2, 3)
    out = jax.vmap(f)(xs)
    assert list(map(float, out["s"])) == [5.0, 50.0]
    assert not (tmp_path / "aot").exists()
    assert float(f(xs[1])["s"]) == 50.0  # concrete: exported and kept
    assert len(list((tmp_path / "aot").iterdir())) == 1


FLAG_PROGRAM = """
    import os
    import jax, jax.numpy as jnp
    from calib_jax.runtime import configure
    {before}
    configure(cache=False)
    print(os.environ.get("XLA_FLAGS", ""))
    print(float(jax.jit(lambda x: jnp.sum(jnp.sin(x) ** 2))(jnp.arange(5.0))))
"""


@pytest.mark.parametrize(
    ("user_flags", "before", "expected_flags"),
    [
        (None, "", "--xla_cpu_use_fusion_emitters=false"),
        ("--xla_cpu_use_fusion_emitters=true", "", "--xla_cpu_use_fusion_emitters=true"),
        (
            "--xla_cpu_enable_fast_math=false",
            "",
            "--xla_cpu_enable_fast_math=false --xla_cpu_use_fusion_emitters=false",
        ),
        (None, "jax.devices()", ""),  # XLA already started: its flags were read, none added
    ],
)
def test_configure_asks_for_short_compiles_unless_the_user_chose(
    user_flags, before, expected_flags
):
    """configure() adds runtime.SHORT_COMPILES_FLAG to XLA_FLAGS (XLA aborts on a flag it does
    not know, so a process that computes shows the flag was taken), keeps a user's own choice
    of that option, keeps their other flags, and adds nothing once XLA has started."""
    from calib_jax import runtime

    if not runtime._flag_measured():
        pytest.skip("jaxlib not among runtime.SHORT_COMPILES_JAXLIB: the flag is never given")
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if user_flags is not None:
        env["XLA_FLAGS"] = user_flags
    r = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(FLAG_PROGRAM.format(before=before))],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    flags, value = r.stdout.splitlines()[-2:]
    assert flags == expected_flags
    assert value == EXPECTED
