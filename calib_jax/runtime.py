"""JAX settings for calibration runs: float64 and the persistent compilation cache.

Every command-line call used to compile its jitted fits from scratch (10-40 s on a 2-core
CPU for a fit SciPy does in 0.01 s). JAX can keep compiled executables on disk and reload them
in the next process; :func:`configure` turns that on in the user's cache directory:

* ``$CALIB_JAX_CACHE_DIR`` if set (``off``, ``0`` or an empty value turns the cache off);
* else ``$XDG_CACHE_HOME/calib_jax/jax`` or ``~/.cache/calib_jax/jax``.

A cache that cannot be created or written is skipped (the fit compiles as before) and the
reason is returned; a corrupt entry is recompiled by JAX itself (it warns and goes on), so the
cache can never break a fit. Measured on the shipped Xsens log (``calibrate_accel``, 2-core
CPU): 18.5 s in a new process without the cache, 4.2 s with a warm one.

:func:`configure` also asks XLA's CPU compiler for its older loop emitter, which compiles the
fits 30-40 % faster (:data:`SHORT_COMPILES_FLAG`, where the measurements are); a user's own
``XLA_FLAGS`` choice of that option is kept.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

_OFF = ("", "0", "off", "false", "no", "none")
_AOT_DIR: list[Path] = []  # where DiskJit keeps exported programs: set by configure()
ENV = "CALIB_JAX_CACHE_DIR"


def cache_dir() -> Path | None:
    """Where compiled code is kept, or None when the user turned the cache off."""
    env = os.environ.get(ENV)
    if env is not None:
        return None if env.strip().lower() in _OFF else Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "calib_jax" / "jax"


def configure(*, x64: bool = True, cache: bool = True) -> str:
    """Turn on float64 and (unless ``cache`` is False or the user turned it off) the
    persistent compilation cache. Returns a one-line account of the cache for reports."""
    import jax

    _prefer_short_compiles()
    if x64:
        jax.config.update("jax_enable_x64", True)
    path = cache_dir() if cache else None
    _AOT_DIR.clear()
    if path is None:
        return "compilation cache off"
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        return f"compilation cache off: {path} is not writable ({exc.strerror or exc})"
    jax.config.update("jax_compilation_cache_dir", str(path))
    _AOT_DIR.append(path / "aot")
    # every fit's compile takes seconds, the smallest helpers milliseconds: keep them all, the
    # cache of a full demo is under 1 MB
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    # a corrupt entry is recompiled; say so once per process, not once per function
    warnings.filterwarnings(
        "once", message="Error reading persistent compilation cache entry", category=UserWarning
    )
    return f"compilation cache {path}"


# XLA's CPU compiler emits fused loops by one of two code generators. Its older one compiles the
# fits' programs (an LM loop around small hand-written solves: thousands of tiny fusions, little
# data) in 30-40 % less time: fit_mag 2.9 -> 1.7 s, the gradient of fit_accel 2.6 -> 1.9 s;
# cold ``calib-jax mag`` 9.1 -> 6.6 s and ``marg`` 15.9 -> 11.8 s; the test suite 13.1 -> 10.6
# min, every test passing with either (2-core CPU, jaxlib 0.10.2). The batch fit (benchmarks/
# batch.py, three runs each way at load 1-2) compiles in 3.3-3.5 s instead of 4.0-4.4 s and runs
# as fast: 0.111-0.115 against 0.109-0.110 ms per sensor at 1,000 sensors, 0.153-0.154 against
# 0.155-0.184 at 100. XLA aborts the process on a flag it does not know, so the flag is only
# given to the jaxlib versions it was measured on.
SHORT_COMPILES_FLAG = "--xla_cpu_use_fusion_emitters=false"
SHORT_COMPILES_JAXLIB = ((0, 10),)  # jaxlib (major, minor) on which the flag was measured


def _prefer_short_compiles() -> None:
    """Add :data:`SHORT_COMPILES_FLAG` to ``XLA_FLAGS`` before XLA starts, unless the user's
    ``XLA_FLAGS`` already chooses the CPU fusion emitters, XLA has started (flags are read once)
    or this jaxlib was not measured."""
    flags = os.environ.get("XLA_FLAGS", "")
    if SHORT_COMPILES_FLAG.split("=")[0] in flags or not _flag_measured():
        return
    from jax._src import xla_bridge  # private: only reached on the jaxlib measured

    if not xla_bridge.backends_are_initialized():
        os.environ["XLA_FLAGS"] = f"{flags} {SHORT_COMPILES_FLAG}".strip()


def _flag_measured() -> bool:
    import jaxlib.version

    major, minor = (int(x) for x in jaxlib.version.__version__.split(".")[:2])
    return (major, minor) in SHORT_COMPILES_JAXLIB


# ---------------------------------------------------------------------------------------------
# compiled fits kept whole on disk


class DiskJit:
    """``jax.jit(fun)`` whose traced and lowered program is also kept on disk, so that a new
    process skips the tracing and lowering as well as the compilation.

    JAX's persistent cache (above) only skips XLA's compile: it is keyed by the lowered
    program, so every new process still traces and lowers each fit, about 1-2 s of a warm CLI
    call on a 2-core CPU. Once :func:`configure` has turned the cache on, a call with concrete
    arrays looks up the program exported by :mod:`jax.export` (JAX's own stable serialization)
    in the cache's ``aot`` folder, keyed by ``key`` (which must name the function and every
    static option), the arguments' shapes and dtypes, the JAX version, x64, the device and
    the source of calib_jax itself (an edited package never loads an old program); its
    compilation then comes from the persistent cache. A call with tracers (inside a user's
    jit, grad or vmap) and a cache that is off, unreadable, corrupt or read-only all fall back
    to the plain ``jax.jit`` call: the disk can never break a fit. Outputs may be arrays,
    tuples, dicts, None and equinox modules (rebuilt field by field).
    """

    def __init__(self, fun, key: str):
        import jax

        self.fun = fun
        self.key = key
        self.jitted = jax.jit(fun)
        self._loaded: dict[str, object] = {}
        self._refused: set[str] = set()  # digests that failed once: plain jit, no retry

    def __call__(self, *args):
        import jax

        leaves, in_tree = jax.tree_util.tree_flatten(args)
        if not _AOT_DIR or any(isinstance(x, jax.core.Tracer) for x in leaves):
            return self.jitted(*args)
        digest = None
        try:
            # device_put, not jnp.asarray: that compiles an identity program per shape (six of
            # them in a warm calib-jax marg, each a disk read)
            leaves = [x if isinstance(x, jax.Array) else jax.device_put(x) for x in leaves]
            digest = self._digest(leaves, in_tree)
            if digest in self._refused:
                return self.jitted(*args)
            exported = self._loaded.get(digest) or self._load_or_export(
                _AOT_DIR[0] / f"{digest}.jaxexport", leaves, in_tree
            )
            self._loaded[digest] = exported
            return _unplain(exported.call(*leaves))
        except Exception as exc:  # noqa: BLE001 - the disk is an optimisation, never a failure
            self._refused.add(digest)  # say it once; later calls go straight to jax.jit
            warnings.warn(f"compiled-fit cache skipped ({type(exc).__name__}: {exc})", stacklevel=2)
            return self.jitted(*args)

    def _digest(self, leaves, in_tree) -> str:
        import hashlib

        avals = [(x.shape, str(x.dtype), bool(getattr(x, "weak_type", False))) for x in leaves]
        parts = (self.key, str(in_tree), avals, _environment())
        return hashlib.sha256(repr(parts).encode()).hexdigest()[:32]

    def _load_or_export(self, path: Path, leaves, in_tree):
        import jax
        from jax import export

        try:
            return export.deserialize(bytearray(path.read_bytes()))
        except FileNotFoundError:
            pass
        except Exception:  # noqa: BLE001 - corrupt or foreign: export again below
            path.unlink(missing_ok=True)

        def flat(*xs):
            return _plain(self.fun(*jax.tree_util.tree_unflatten(in_tree, list(xs))))

        # custom calls (LAPACK through lineax) with no cross-version guarantee are allowed: the
        # key holds the JAX version, so the program only ever runs where it was made
        targets: set[str] = set()
        for _ in range(4):
            checks = [export.DisabledSafetyCheck.custom_call(t) for t in sorted(targets)]
            try:
                exported = export.export(jax.jit(flat), disabled_checks=checks)(*leaves)
                break
            except ValueError as exc:
                found = set(re.findall(r"custom_call @(\w+)", str(exc))) - targets
                if not found:
                    raise
                targets |= found
        else:
            raise ValueError(f"custom calls still refused after allowing {sorted(targets)}")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(exported.serialize())
            os.replace(tmp, path)  # atomic: a reader never sees half a file
        except OSError:
            pass  # read-only or full disk: this process keeps the program in memory
        return exported


def disk_jit(fun, key: str) -> DiskJit:
    """:class:`DiskJit`: ``jax.jit(fun)`` with whole executables kept on disk under ``key``."""
    return DiskJit(fun, key)


_ENV_DIGEST: list[str] = []


def _environment() -> str:
    """What an exported program depends on besides its arguments: JAX, x64, the device and
    calib_jax's own source (hashed once per process)."""
    if _ENV_DIGEST:
        return _ENV_DIGEST[0]
    import hashlib

    import jax

    h = hashlib.sha256()
    for f in sorted(Path(__file__).resolve().parent.rglob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    dev = jax.devices()[0]
    h.update(repr((jax.__version__, jax.config.jax_enable_x64, dev.platform)).encode())
    _ENV_DIGEST.append(h.hexdigest())
    return _ENV_DIGEST[0]


_TAG = "__equinox__ "


def _plain(tree):
    """Equinox modules -> {"__equinox__ module:class": {field: value}}: the class lives in a
    dict key, part of the tree's structure (a plain dict's structure pickles; a module's does
    not load), never a leaf."""
    import dataclasses

    import equinox as eqx

    if isinstance(tree, eqx.Module):
        cls = type(tree)
        fields = {f.name: _plain(getattr(tree, f.name)) for f in dataclasses.fields(tree)}
        return {f"{_TAG}{cls.__module__}:{cls.__qualname__}": fields}
    if isinstance(tree, tuple | list):
        return type(tree)(_plain(x) for x in tree)
    if isinstance(tree, dict):
        return {k: _plain(v) for k, v in tree.items()}
    return tree


def _unplain(tree):
    import importlib

    if isinstance(tree, dict) and len(tree) == 1:
        ((key, fields),) = tree.items()
        if isinstance(key, str) and key.startswith(_TAG):
            module, name = key[len(_TAG) :].split(":")
            cls = importlib.import_module(module)
            for part in name.split("."):
                cls = getattr(cls, part)
            obj = object.__new__(cls)
            for field, value in fields.items():
                object.__setattr__(obj, field, _unplain(value))
            return obj
    if isinstance(tree, tuple | list):
        return type(tree)(_unplain(x) for x in tree)
    if isinstance(tree, dict):
        return {k: _unplain(v) for k, v in tree.items()}
    return tree
